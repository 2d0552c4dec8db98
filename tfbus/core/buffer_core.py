"""BufferCore: the frame graph and its lookups — synchronous and sans-I/O.

This is tf2's ``BufferCore`` (ROS 1 geometry2 0.7.6, ``tf2/src/buffer_core.cpp``)
re-implemented with the same semantics (API and messages here; storage, insert and the
walk in the core chosen by :mod:`tfbus.core._select`: compiled from ``tfbus/core/_c*.pyx``, or
its pure-Python twins ``tfbus/core/_py*.py``, bit for bit the same), checked against vectors
recorded from the real tf2 (``tests/data/public.jsonl.gz`` and ``tf2_regressions.jsonl``):

* ``lookup_transform(target, source, t)`` returns the pose of ``source`` in ``target``
  (it maps points from source into target coordinates); ``header.stamp`` is the time used.
* Time 0 means the *latest common time* of the path: the minimum over the dynamic links
  between the two frames of each link's newest stamp, ignoring static links and links
  whose newest stamp is 0 (``getLatestCommonTime``).
* No extrapolation, not even 1 ns; interpolation is linear in translation and tf2's
  shortest-path slerp in rotation; only the path between the two frames must be valid
  (``walkToTopParent``).
* Quaternions are not normalised; inputs must be within 0.01 of unit norm (squared).

One intended deviation from tf2: a translation with ±Inf is rejected
(``InvalidArgumentException``) where tf2 stores it and later returns NaN.
Messages of exceptions are tf2's, character for character.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable, Iterator
from typing import TYPE_CHECKING, Any, Final, Literal, NoReturn, TypeAlias, overload

import numpy as np
import numpy.typing as npt

from tfbus.core._select import (
    COMPILED,
    CONNECTIVITY_ERROR,
    EXTRAPOLATION_ERROR,
    INVALID,
    INVALID_ARGUMENT,
    LOOKUP_ERROR,
    MAX_GRAPH_DEPTH,
    OLD_DATA,
    UNKNOWN_FRAME,
    CoreBase,
    compose_full,
    lookup_rows,
)
from tfbus.core.batch import (
    Errors,
    TimesLike,
    TransformArray,
    as_times,
    check_errors,
    compose_rows,
    single_lookups,
)
from tfbus.core.policy import (
    Clamp,
    Exact,
    ExpireAfter,
    LookupPolicy,
    Nearest,
    PolicyReport,
    PolicyResult,
    Previous,
    Window,
    policy_args,
    policy_error,
)
from tfbus.core.results import (
    BatchResult,
    BufferStatistics,
    SetResult,
    TouchedFrames,
    cache_time_ns,
    cap_message,
    not_a_time,
)
from tfbus.core.text import (
    FrameInfo,
    Tf7,
    bad_frame_exception,
    frames_as_dot,
    frames_as_string,
    frames_as_yaml,
    invalid_transform_exception,
)
from tfbus.core.velocity import lookup_velocity as _lookup_velocity
from tfbus.errors import (
    BackwardExtrapolationException,
    ConnectivityException,
    InvalidArgumentException,
    LookupException,
    TransformException,
    extrapolation_exception,
)
from tfbus.messages import (
    Header,
    Quaternion,
    Transform,
    TransformStamped,
    Vector3,
    VelocityStamped,
)
from tfbus.ratelimit import CountLimitedLog
from tfbus.time import TIME_MAX_NS, Duration, Time

__all__ = [
    "COMPILED",
    "MAX_GRAPH_DEPTH",
    "BatchResult",
    "BufferCore",
    "BufferStatistics",
    "FrameInfo",
    "OnRepeat",
    "SetResult",
    "Tf7",
    "frame_path",
]

logger = logging.getLogger("tfbus.core")

OnRepeat: TypeAlias = Literal["reject", "replace"]
"""``BufferCore(on_repeat=...)``: refuse (tf2) or replace a sample at the newest stamp."""

_REFUSAL_LOG_EVERY: Final = 1000  # one TF_OLD_DATA / TF_REPEATED_DATA line per 1000

_LATEST: Final = Time(0)


def frame_path(parents: dict[str, str], source: str, target: str) -> list[str] | None:
    """The frames from ``source`` up to the lowest common ancestor and down to
    ``target`` (tf2 ``_chainAsVector``'s order without tf2 0.7.6's pruning quirk, as
    tf_monitor measures a chain), given each child frame's parent; ``[source]`` when
    the two are one; None when the two frames are in different trees (or in a loop).
    tfbus's one frame path: :meth:`BufferCore.frame_path`, the monitor and tf_echo use
    it (the tf2_py 0.7.6 ordering with its quirks is :func:`tfbus.compat.tf2_py.chain`)."""

    def up(frame: str) -> list[str]:
        walk = [frame]
        while walk[-1] in parents and parents[walk[-1]] not in walk:
            walk.append(parents[walk[-1]])
        return walk

    if source == target:
        return [source]
    a, b = up(source), up(target)
    in_b = {frame: j for j, frame in enumerate(b)}
    for i, frame in enumerate(a):
        j = in_b.get(frame)
        if j is not None:
            return a[: i + 1] + b[:j][::-1]
    return None


class _CoreOnly:
    """A method of the core (``CoreBase``) kept off ``BufferCore``'s public surface: its
    public name is another (tf2's), so reading it from a buffer raises AttributeError
    naming that one, and ``dir()`` leaves it out. :meth:`call` still reaches the core's
    method (the next one along the instance type's MRO).
    """

    __slots__ = ("_found", "name", "public")

    def __init__(self, public: str) -> None:
        self.public = public
        self.name = ""
        self._found: dict[type, Any] = {}

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, obj: object, owner: type | None = None) -> Any:
        kind = owner.__name__ if owner is not None else type(obj).__name__
        raise AttributeError(
            f"{kind!r} object has no attribute {self.name!r}. Did you mean: {self.public}?",
            name=self.name,
            obj=obj,
        )

    def call(self, obj: object, *args: Any) -> Any:
        """The core's method of this name, called on ``obj``."""
        kind = type(obj)
        method = self._found.get(kind)
        if method is None:
            method = next(
                found
                for klass in kind.__mro__
                if (found := vars(klass).get(self.name)) is not None and found is not self
            )
            self._found[kind] = method
        return method(obj, *args)


_PARENT_OF: Final = _CoreOnly(
    "'get_parent(frame_id, time=Time(0))' (tf2's BufferCore::_getParent; time a Time, not ns)"
)


class BufferCore(CoreBase):
    """tf2's transform buffer: stores stamped transforms per link and answers lookups.

    Args:
        cache_time: how long to keep each dynamic link's history, seconds (a real number,
            not a bool) or a :class:`~tfbus.time.Duration`, in [0, 2**63 - 1] ns. Expiry
            happens per link on insert, relative to that link's newest stamp, exactly as
            in tf2 (no wall clock is involved).
        on_repeat: what a dynamic transform whose stamp equals a stored sample of its
            link does. ``"reject"`` (default, tf2's ``TimeCache::insertData`` in geometry2
            0.7.6): refused and logged as TF_REPEATED_DATA, the first sample wins.
            ``"replace"``: when that sample is the link's newest, the new values and
            parent replace it (a stored transform; a publisher re-sending a corrected
            pose at the same stamp); an equal stamp older than the newest is still
            refused as TF_REPEATED_DATA. Static transforms always replace (tf2).
        cache_policy: None (default, tf2: a frame is kept for the life of the buffer) or
            :func:`~tfbus.core.policy.expire_after` ``(seconds)``: as data arrives, the
            dynamic links whose newest sample is more than ``seconds`` older than the
            newest dynamic stamp stored are removed by :meth:`forget` (at most once per
            ``every`` of stamp time, 1 s by default), counted in
            :meth:`statistics` ``.frames_expired``.

    Raises:
        TypeError: ``cache_time`` is not a number or Duration (checked before anything is
            allocated); ``cache_policy`` is not an ``expire_after(...)``.
        ValueError: ``cache_time`` is negative, infinite, NaN or beyond int64 ns;
            ``on_repeat`` is neither ``"reject"`` nor ``"replace"``; a ``cache_policy``
            whose durations are not in [1, 2**63 - 1] ns.

    Frame ids are arbitrary strings compared exactly (a ``str`` subclass such as
    ``numpy.str_`` is taken as the string it is). ``set_transform`` strips one leading
    ``/`` (tf2 ``stripSlash``); queries reject ids that start with ``/``. Not thread-safe:
    use it from one thread (or one event loop), as tfbus does.

    Storage, insert, the walk and building results are in the core (compiled from
    :mod:`tfbus.core._ccore`, Cython, or the pure-Python :mod:`tfbus.core._pycore`; ``COMPILED``
    says which) and report what they did as return values; this class turns those into
    tf2's messages, exceptions and (count-limited) log lines.
    """

    def __init__(
        self,
        cache_time: float | Duration = 10.0,
        *,
        on_repeat: OnRepeat = "reject",
        cache_policy: ExpireAfter | None = None,
    ) -> None:
        self._set_cache_time_ns(cache_time_ns(cache_time))
        if on_repeat != "reject":  # (the core's default: nothing to set)
            if on_repeat != "replace":
                raise ValueError(
                    f"on_repeat must be 'reject' or 'replace', got {on_repeat!r}"
                )
            self._set_replace_repeated(True)
        if cache_policy is not None:
            if not isinstance(cache_policy, ExpireAfter):
                raise TypeError(
                    "cache_policy must be None or expire_after(seconds), got "
                    f"{cache_policy!r}"
                )
            for name, ns in zip(("after_ns", "every_ns"), cache_policy, strict=True):
                if type(ns) is not int or not 0 < ns <= TIME_MAX_NS:
                    raise ValueError(
                        f"cache_policy.{name} must be an int in [1, 2**63 - 1] ns, got {ns!r}"
                    )
            self._set_expiry(cache_policy.after_ns, cache_policy.every_ns)
        self._cache_policy = cache_policy
        self._refusal_log = CountLimitedLog(logger, _REFUSAL_LOG_EVERY)

    @property
    def cache_policy(self) -> ExpireAfter | None:
        """The frame expiry given at construction (``expire_after(...)``), or None."""
        return self._cache_policy

    def forget(self, older_than: Time | int) -> int:
        """Remove the frames whose data stopped before ``older_than`` (what tf2 never
        does: ros/geometry2 #239, #409; ``cache_policy=expire_after(...)`` calls this as
        data arrives).

        The rule, per dynamic link (a child frame and its parent): the link is removed
        when its newest sample is older than ``older_than`` (``newest < older_than``),
        whatever its children do; static links never expire. A frame id stays known
        while it has a link or a remaining link has named it as a parent; else it
        becomes unknown exactly as if never seen: lookups raise LookupException ("...
        does not exist"), :meth:`get_frame_names`, :meth:`all_frames_as_string` and
        :meth:`all_frames_as_yaml` leave it out, and a later transform registers it
        anew (its number may be reused). A child whose parent's link was removed keeps
        that parent, now a root: lookups across it raise ConnectivityException (two
        trees), as tf2 reports unconnected frames. The buffer then answers every lookup
        as a fresh buffer fed only the samples of the remaining links would.

        Cost: O((r + k) log n) for r links removed and k links whose newest stamp moved
        past ``older_than`` since the last call (each link is kept in a heap by the
        newest stamp seen when last examined), never a scan of every frame; no cost on
        insert but a heap push when a link is created.

        Args:
            older_than: a :class:`~tfbus.time.Time`, or int nanoseconds in
                [0, 2**63 - 1].

        Returns:
            The number of links removed (frames whose own transform data expired).

        Raises:
            TypeError: ``older_than`` is neither a Time nor an int (a bool included).
            ValueError: an int outside [0, 2**63 - 1].
        """
        if isinstance(older_than, Time):
            ns = older_than.ns
        elif type(older_than) is int or (
            isinstance(older_than, (int, np.integer)) and not isinstance(older_than, bool)
        ):
            ns = int(older_than)
            if not 0 <= ns <= TIME_MAX_NS:
                raise ValueError(
                    f"forget: older_than must be in [0, 2**63 - 1] ns, got {older_than!r}"
                )
        else:
            raise TypeError(
                "forget: older_than must be a tfbus Time or int nanoseconds, got "
                f"{type(older_than).__name__} {older_than!r}"
            )
        return self._forget(ns)

    def statistics(self) -> BufferStatistics:
        """A snapshot of the buffer's counters: frames known, links, and frames expired
        by ``cache_policy``."""
        return BufferStatistics(
            frames=len(self.get_frame_names()),
            links=sum(1 for cache in self._caches[1:] if cache is not None),
            frames_expired=self.frames_expired,
        )

    @property
    def on_repeat(self) -> OnRepeat:
        """``"reject"`` or ``"replace"``: what a transform at the stamp of a stored sample
        of its link does (see the class docstring; fixed at construction)."""
        return "replace" if self.replace_repeated else "reject"

    # ------------------------------------------------------------------ inserting

    @property
    def cache_time(self) -> Duration:
        """The history kept per dynamic link (``cache_time_ns`` as a Duration)."""
        return Duration.from_ns(self.cache_time_ns)

    if TYPE_CHECKING:
        # At run time these three are the core's own methods (``CoreBase``, compiled or
        # pure), inherited: the caller reaches the insert with no Python frame of this
        # class in between, and a transform not stored comes back through
        # ``_not_stored``. Declared here for the type checker and the API reference.

        def set_transform(
            self, transform: TransformStamped, authority: str = "default"
        ) -> bool:
            """Store a dynamic transform (tf2 ``BufferCore::setTransform``).

            Args:
                transform: ``header.frame_id`` is the parent, ``child_frame_id`` the child,
                    ``header.stamp`` the time; translation in metres, rotation (x, y, z, w).
                authority: who sent it (shown by ``all_frames_as_yaml``).

            Returns:
                True when stored (or, with ``on_repeat="replace"``, when it replaced the
                link's newest sample); False when the link's cache refused it — TF_OLD_DATA
                (older than its newest stamp minus ``cache_time``) or TF_REPEATED_DATA (a
                sample with this stamp exists) — which is logged (the first, then one per
                1000).

            Raises:
                InvalidArgumentException: malformed transform — self transform, empty
                    frame id, NaN, ±Inf in the translation, or a quaternion whose squared
                    norm is not within 0.01 of 1; or a field of the wrong type (None, a str
                    or bool where a number belongs, an int beyond double range, ...). The
                    message names each field and value; ``.codes`` holds tf2's ``TF_*`` codes
                    in tf2's order. Nothing is stored, no frame is registered.
                TypeError: ``transform`` is not a TransformStamped, or ``authority`` not a str.
            """
            return CoreBase.set_transform(self, transform, authority)

        def set_transform_static(
            self, transform: TransformStamped, authority: str = "default"
        ) -> bool:
            """Store a static transform: valid at all times, overwritten by every later send
            (tf2 ``setTransform(..., is_static=true)``). Whether a link is static is fixed by
            its first accepted transform, as in tf2.

            Returns and raises as :meth:`set_transform`.
            """
            return CoreBase.set_transform_static(self, transform, authority)

        def set_transforms(
            self,
            transforms: Iterable[TransformStamped],
            authority: str = "default",
            is_static: bool = False,
        ) -> BatchResult:
            """Store a batch of transforms (a ``TFMessage``'s worth) in one call: what the
            listener uses. Per transform it is cheaper than a loop of
            :meth:`set_transform` from about five transforms a call on and within a few
            percent of it at two; one transform a call pays for the :class:`BatchResult`
            beside the insert, about 1.2 to 1.4 times the loop's time (``make
            bench-check`` prints the ratio by message size).

            Each item is handled exactly as :meth:`set_transform` (or
            :meth:`set_transform_static` when ``is_static``) would, in order; an invalid or
            malformed item is reported in ``errors`` instead of raising, and never stops the
            items after it. Refusals (TF_OLD_DATA, TF_REPEATED_DATA) are logged, the first
            of each kind then one per 1000.

            Returns:
                A :class:`BatchResult`: counts, errors, and the frames it touched (what a
                subclass needs to react to the insert, e.g. ``Buffer``'s waits).
            """
            return CoreBase.set_transforms(self, transforms, authority, is_static)

    def insert_transform(
        self, transform: TransformStamped, authority: str = "default", is_static: bool = False
    ) -> SetResult:
        """Like :meth:`set_transform` / :meth:`set_transform_static`, but tells why a
        transform was refused. Raises as :meth:`set_transform`.

        The three store one transform through the core's ``_store_one`` (what
        :meth:`set_transforms` does per item, with nothing built on success)."""
        r = self._store_one(transform, authority, is_static)
        return SetResult.STORED if r is True else self._not_stored(r, authority)

    def _not_stored(self, problem: tuple[Any, ...], authority: str) -> SetResult:
        """What ``_store_one`` reported for a transform it did not store: log a refusal
        (count-limited) and say which, or raise tf2's InvalidArgumentException."""
        if problem[0] == INVALID:
            _, parent, child, values = problem
            raise invalid_transform_exception(parent, child, values, authority)
        self._log_refusals([problem], authority)
        return SetResult.OLD_DATA if problem[0] == OLD_DATA else SetResult.REPEATED_DATA

    def _batch_result(
        self,
        r: tuple[
            int,
            list[tuple[int, Exception | tuple[str, str, Tf7]]],
            TouchedFrames,
            bool,
            list[tuple[int, str, int]],
        ],
        authority: str,
    ) -> BatchResult:
        """The BatchResult of a batch ``_store`` refused or rejected some of: refusals
        logged (count-limited), tf2's exception built for each invalid transform."""
        stored, problems, touched, relinked, refusals = r
        if refusals:
            self._log_refusals(refusals, authority)
        errors: list[tuple[int, Exception]] = [
            (i, p if isinstance(p, Exception) else invalid_transform_exception(*p, authority))
            for i, p in problems
        ]
        return BatchResult(stored, len(refusals), errors, touched, relinked)

    def _log_refusals(self, refusals: list[tuple[int, str, int]], authority: str) -> None:
        """Log refusals by the caches in tf2's words (count-limited)."""
        for code, child, stamp in refusals:
            if code == OLD_DATA:
                self._refusal_log.log(
                    logging.WARNING,
                    "TF_OLD_DATA ignoring data from the past (Possible reasons are listed at "
                    "http://wiki.ros.org/tf/Errors%%20explained) for frame %s at time %f "
                    "according to authority %s",
                    child,
                    stamp / 1e9,
                    authority,
                )
            else:
                self._refusal_log.log(
                    logging.WARNING,
                    "TF_REPEATED_DATA ignoring data with redundant timestamp for frame %s "
                    "at time %f according to authority %s",
                    child,
                    stamp / 1e9,
                    authority,
                )

    # ------------------------------------------------------------------ failures

    def _failure(
        self, function: str, target: str, source: str, failure: tuple[int, ...]
    ) -> TransformException:
        """tf2's exception for a failure tuple of the compiled query (``CoreBase._query``)."""
        code = failure[0]
        if code == EXTRAPOLATION_ERROR:
            detail = self.extrapolation_detail(failure[1], failure[2])
            return extrapolation_exception(
                cap_message(
                    f"{detail}, when looking up transform from frame [{source}] "
                    f"to frame [{target}]"
                )
            )
        if code == CONNECTIVITY_ERROR:
            return ConnectivityException(
                f"Could not find a connection between '{target}' and '{source}' because "
                "they are not part of the same tree.Tf has two or more unconnected trees."
            )
        if code == LOOKUP_ERROR:
            return LookupException(
                "The tf tree is invalid because it contains a loop.\n"
                + self.all_frames_as_string()
                + "\n"
            )
        if failure[1] == 0:
            return bad_frame_exception(f"{function} argument target_frame", target, code)
        return bad_frame_exception(f"{function} argument source_frame", source, code)

    def invalid_frame_id(
        self, frame_id: str, argument: str = "lookupTransform argument frame_id"
    ) -> InvalidArgumentException | None:
        """tf2 ``validateFrameId``'s form check alone: the InvalidArgumentException a
        query would raise for ``frame_id`` (empty, '/'-prefixed, not a string), naming
        ``argument``; None for a well-formed id, known or not (what a wait needs: an
        unknown id may still arrive)."""
        if self._id_status(frame_id) == INVALID_ARGUMENT:
            error = bad_frame_exception(argument, frame_id, INVALID_ARGUMENT)
            assert isinstance(error, InvalidArgumentException)
            return error
        return None

    def _validate(self, label: str, frame_id: str) -> None:
        """tf2 ``validateFrameId``: raise for an empty, '/'-prefixed or unknown id."""
        code = self._id_status(frame_id)
        if code:
            raise bad_frame_exception(label, frame_id, code)

    # ------------------------------------------------------------------ lookups

    if TYPE_CHECKING:
        # At run time lookup_transform is the core's own (``CoreBase``, compiled or
        # pure), inherited: an exact lookup reaches the walk with no Python frame of
        # this class in between; a policy, a failure or a bad ``time`` comes back through
        # ``_lookup_by_policy`` / ``_lookup_failed``. Declared here for the type checker
        # and the API reference.

        @overload
        def lookup_transform(
            self, target_frame: str, source_frame: str, time: Time, *, policy: Exact | None = None
        ) -> TransformStamped: ...

        @overload
        def lookup_transform(
            self,
            target_frame: str,
            source_frame: str,
            time: Time,
            *,
            policy: Nearest | Clamp | Previous | Window,
        ) -> PolicyResult: ...

        # ``policy`` is keyword-only in the signatures above (what type checkers hold callers
        # to), not in the core's method: a keyword-only default costs every exact lookup a dict
        # lookup (CPython's __kwdefaults__), ~10% of a memoised answer.
        def lookup_transform(
            self,
            target_frame: str,
            source_frame: str,
            time: Time,
            policy: LookupPolicy | None = None,
        ) -> TransformStamped | PolicyResult:
            """The pose of ``source_frame`` in ``target_frame`` at ``time`` (tf2
            ``lookupTransform``): it maps points from source into target coordinates.

            Args:
                target_frame: frame to express data in.
                source_frame: frame the data is in.
                time: when; ``Time(0)`` means the latest time the whole path has data for.

            Returns:
                TransformStamped with ``header.frame_id == target_frame``,
                ``child_frame_id == source_frame`` and ``header.stamp`` the time used.
                ``lookup_transform(x, x, t)`` is the identity for any string x.

            Raises:
                InvalidArgumentException: a frame id is empty or starts with '/'.
                LookupException: a frame id is unknown, or the path contains a loop.
                ConnectivityException: the frames are in different trees.
                ExtrapolationException: a link on the path has no data at ``time``: its ROS 2
                    subclass ``ForwardExtrapolationException`` (after the link's newest
                    sample), ``BackwardExtrapolationException`` (before its oldest) or
                    ``NoDataForExtrapolationException`` (one sample at another time, or none),
                    as rolling tf2's ``TimeCache::findClosest`` chooses; tf2 0.7.6's message.
                    Under a policy: for the first link the policy found no sample for, the
                    exception and message of the exact lookup for that link.
                TypeError: ``policy`` is not a lookup policy, or ``time`` not a Time.

            ``policy`` (:mod:`tfbus.core.policy`): how each link's sample is picked;
            ``None`` or :class:`~tfbus.core.policy.Exact` is tf2's rule and returns the
            TransformStamped. Any other policy (``Nearest(max_delta)``, ``Clamp(max_delta)``,
            ``Previous()``, ``Window(past, future_wait)``) returns a
            :class:`~tfbus.core.policy.PolicyResult` ``(transform, report)``: the report names
            each link's sample stamp and the largest ``|stamp - time|``, so no approximation
            is silent. Policy lookups are not memoised.

            One compiled call validates, walks and builds the result. Successful results are
            memoised until the next insert or ``clear()`` (64 slots, by the ids' identity and
            the time), so repeating a query (many objects at one stamp, time 0 between
            updates) costs a few compares.
            """
            if policy is None:
                return CoreBase.lookup_transform(self, target_frame, source_frame, time)
            return self._lookup_by_policy(target_frame, source_frame, time, policy)

    def _lookup_by_policy(
        self, target_frame: str, source_frame: str, time: Time, policy: object
    ) -> TransformStamped | PolicyResult:
        """:meth:`lookup_transform` with a ``policy`` given: :class:`Exact` is the exact
        lookup, any other policy its :class:`PolicyResult` (or raises)."""
        if type(policy) is Exact:
            return CoreBase.lookup_transform(self, target_frame, source_frame, time)
        try:
            found = self._query_policy(target_frame, source_frame, time,
                                       policy._args)  # type: ignore[attr-defined]
        except AttributeError as err:
            raise policy_error(policy, time, err) from None
        if isinstance(found, PolicyResult):
            return found
        raise self._failure("lookupTransform", target_frame, source_frame, found)

    def _lookup_failed(
        self, target_frame: str, source_frame: str, time: object,
        why: tuple[int, ...] | AttributeError,
    ) -> NoReturn:
        """Raise what an exact lookup failed with: ``why`` is the core's failure tuple,
        or the AttributeError of a ``time`` that is not a Time."""
        if isinstance(why, AttributeError):
            raise not_a_time(time, why) from None
        raise self._failure("lookupTransform", target_frame, source_frame, why)

    def _policy_query(
        self, target_frame: str, source_frame: str, time: Time, policy: object
    ) -> PolicyResult | tuple[int, ...]:
        """The core's policy lookup: the PolicyResult or a failure tuple (``_query``'s)."""
        try:
            out: PolicyResult | tuple[int, ...] = self._query_policy(
                target_frame, source_frame, time, policy_args(policy)
            )
        except AttributeError as err:
            raise not_a_time(time, err) from None
        return out

    def _lookup_policy(
        self, target_frame: str, source_frame: str, time: Time, policy: object
    ) -> PolicyResult:
        """:meth:`lookup_transform` under a policy, always its PolicyResult (or raises)."""
        found = self._policy_query(target_frame, source_frame, time, policy)
        if isinstance(found, PolicyResult):
            return found
        raise self._failure("lookupTransform", target_frame, source_frame, found)

    def try_lookup_transform(
        self, target_frame: str, source_frame: str, time: Time
    ) -> TransformStamped | TransformException:
        """:meth:`lookup_transform` in one walk that returns instead of raising: the
        transform, or the exception ``lookup_transform`` would raise (why not)."""
        try:
            out = self._query(target_frame, source_frame, time)
        except AttributeError as err:  # (no cost on the way through)
            raise not_a_time(time, err) from None
        if isinstance(out, TransformStamped):
            return out
        return self._failure("lookupTransform", target_frame, source_frame, out)

    def check_transform(
        self, target_frame: str, source_frame: str, time: Time, fail_fast: bool = False
    ) -> TransformStamped | TransformException | None:
        """What a wait for ``lookup_transform(target_frame, source_frame, time)`` should do
        now, in one walk (tf2's transformable requests, ``testTransformableRequests``):

        Args:
            fail_fast: also give up when the data can never come (see Returns); False is
                tf2_ros's behaviour, which waits for its whole timeout then.

        Returns:
            The transform when available; the exception when waiting cannot help — an
            invalid id (InvalidArgumentException), a loop in the path (LookupException),
            or ``time`` older than the path's latest common time minus ``cache_time``
            (ExtrapolationException); None while it may still become available (unknown
            frames, unconnected trees, no data yet at ``time``). With ``fail_fast``, also
            the exception when the two frames are known and in different trees
            (ConnectivityException), and when a dynamic link of the path between them
            (by each link's newest parent) can never answer ``time``: ``time`` is older
            than that link's newest stamp minus ``cache_time``, the oldest stamp its cache
            still accepts (tf2 ``TimeCache::insertData`` refuses older data as
            TF_OLD_DATA) (BackwardExtrapolationException, tf2's message for that link).
        """
        try:
            out = self._query(target_frame, source_frame, time)
        except AttributeError as err:  # (no cost on the way through)
            raise not_a_time(time, err) from None
        if isinstance(out, TransformStamped):
            return out
        return self._hopeless(target_frame, source_frame, out, time, fail_fast)

    def check_transform_policy(
        self, target_frame: str, source_frame: str, time: Time, policy: LookupPolicy
    ) -> PolicyResult | TransformException | None:
        """:meth:`check_transform` under a lookup policy (:mod:`tfbus.core.policy`): the
        :class:`~tfbus.core.policy.PolicyResult` when the policy can answer, the
        exception when waiting cannot help, None while it may (what an awaited policy
        lookup rechecks on every insert of its frames). ``Exact()`` answers with a
        report whose every stamp is the time used (tf2's answer, bit for bit).

        Raises:
            TypeError: ``policy`` is not a lookup policy, or ``time`` not a Time.
        """
        out = self._policy_query(target_frame, source_frame, time, policy)
        if isinstance(out, PolicyResult):
            return out
        return self._hopeless(target_frame, source_frame, out, time, False)

    def _hopeless(
        self,
        target_frame: str,
        source_frame: str,
        out: tuple[int, ...],
        time: Time,
        fail_fast: bool,
    ) -> TransformException | None:
        """The exception of a failure tuple when waiting cannot help (with ``fail_fast``,
        also when the data can never come: :meth:`_fail_fast_error`), else None."""
        code = out[0]
        if code in (INVALID_ARGUMENT, LOOKUP_ERROR) or (code == EXTRAPOLATION_ERROR and out[3]):
            return self._failure("lookupTransform", target_frame, source_frame, out)
        if fail_fast and code in (CONNECTIVITY_ERROR, EXTRAPOLATION_ERROR):
            return self._fail_fast_error(target_frame, source_frame, time, out)
        # An unknown target is reported first (tf2's order), but an invalid source makes
        # the wait hopeless all the same.
        if (
            code == UNKNOWN_FRAME
            and out[1] == 0
            and self._id_status(source_frame) == INVALID_ARGUMENT
        ):
            return self._failure(
                "lookupTransform", target_frame, source_frame, (INVALID_ARGUMENT, 1)
            )
        return None

    def _fail_fast_error(
        self, target: str, source: str, time: Time, failure: tuple[int, ...]
    ) -> TransformException | None:
        """For a wait with ``fail_fast``: the exception of a failed query (connectivity or
        extrapolation ``failure`` of ``_query`` for ``time``) that no later insert can
        cure, else None.

        * Two known frames in different trees (the walk at the time, or the frames'
          newest parents for an extrapolation failure): ConnectivityException.
        * A dynamic link the lookup needs — on the path between the two frames by each
          link's newest parent, source side first (the link tf2's walk failed on may be
          one it would not need once others have data: the target's own link when the
          target is an ancestor of the source) — whose newest stamp minus
          ``cache_time`` is after ``time``: its cache refuses an
          insert that old (TF_OLD_DATA, tf2 ``TimeCache::insertData``) and pruning kept
          nothing older, so it can never answer ``time``. BackwardExtrapolationException
          with tf2's message for that link.

        ``Time(0)`` (the latest common time) is never hopeless for lack of data: newer
        data moves it.
        """
        if failure[0] == CONNECTIVITY_ERROR:
            return self._failure("lookupTransform", target, source, failure)
        ids = self._frame_ids
        target_id, source_id = ids[target], ids[source]
        err = self._ccommon_time(target_id, source_id)[0]
        if err == CONNECTIVITY_ERROR:
            return self._failure("lookupTransform", target, source, (CONNECTIVITY_ERROR, 0))
        if time.ns == 0 or err != 0:
            return None
        used = failure[2]
        horizon = used + self.cache_time_ns
        caches = self._caches
        for fid in self._links_between(source_id, target_id):
            link = caches[fid] if 0 < fid < len(caches) else None
            if link is None or link.is_static:
                continue
            newest = link.latest_stamp()
            if newest > horizon:  # used < newest - cache_time, without overflow
                error = self._failure(
                    "lookupTransform", target, source, (EXTRAPOLATION_ERROR, fid, used)
                )
                if isinstance(error, BackwardExtrapolationException):
                    return error
                # One sample, at a later time: rolling names that NoDataForExtrapolation,
                # but the time asked is before anything the link can still hold.
                return BackwardExtrapolationException(str(error))
        return None

    def _links_between(self, source_id: int, target_id: int) -> list[int]:
        """The child frame ids of the links between two frames by each link's newest
        parent (source side, then target side; the lowest common ancestor's own link
        excluded); empty when they share no ancestor (at most ``MAX_GRAPH_DEPTH`` + 1
        frames a side)."""
        caches = self._caches

        def up(frame: int) -> list[int]:
            walk, seen = [frame], {frame}
            while len(walk) <= MAX_GRAPH_DEPTH:
                link = caches[frame] if 0 < frame < len(caches) else None
                if link is None:
                    break
                frame = link.latest()[1]
                if frame == 0 or frame in seen:
                    break
                walk.append(frame)
                seen.add(frame)
            return walk

        a, b = up(source_id), up(target_id)
        in_b = {frame: j for j, frame in enumerate(b)}
        for i, frame in enumerate(a):
            j = in_b.get(frame)
            if j is not None:
                return a[:i] + b[:j]
        return []

    # ------------------------------------------------------------------ batched lookups

    def lookup_transforms(
        self,
        target_frame: str,
        source_frame: str,
        times: TimesLike,
        *,
        errors: Errors = "raise",
        policy: LookupPolicy | None = None,
    ) -> TransformArray:
        """``lookup_transform(target_frame, source_frame, t)`` for every t of ``times``
        (one batch): the path is resolved once, every time is walked along it in the core.

        Args:
            target_frame: frame to express data in.
            source_frame: frame the data is in.
            times: ``(N,) int64`` nanoseconds (or Times); 0 means latest, as in tf2.
            errors: ``"raise"`` (default) or ``"mask"``: failed rows become NaN with
                ``valid[i] = False`` and the call does not raise for missing data; each
                failed row's reason is the exception the single lookup raises for it
                (asked once per distinct failing time): ``error_codes`` (ROS 2 tf2's
                :class:`~tfbus.errors.TF2Error`), ``error(i)``, ``error_message(i)``.

        Returns:
            A :class:`~tfbus.core.batch.TransformArray` whose row i equals
            ``lookup_transform`` at ``times[i]`` (stamp = the time used; values to the
            bit, or within 1e-12 where the compiled core vectorises slerp's sines: see
            :mod:`tfbus.core.batch`).

        Raises:
            InvalidArgumentException: a frame id is empty or starts with '/' (always, as
                the single lookup validates before looking at times).
            LookupException, ConnectivityException, ExtrapolationException: with
                ``errors="raise"``, the exception and message the single lookup raises
                for the first time that cannot be answered. With ``errors="mask"`` an
                unknown frame id still raises LookupException (no row could ever be
                answered).
            ValueError: ``times`` or ``errors`` is malformed.
            TypeError: ``policy`` is not a lookup policy.

        ``policy`` (:mod:`tfbus.core.policy`): a non-exact policy answers each row as
        ``lookup_transform(..., policy=policy)`` does (the core's policy walk per row,
        not vectorised) and fills the result's ``reports`` and ``max_abs_delta_ns``.

        Source: tf2 ``BufferCore::lookupTransform`` / ``walkToTopParent`` per time.
        """
        check_errors(errors)
        t = as_times(times)
        if policy is not None and type(policy) is not Exact:
            return self._policy_rows(target_frame, source_frame, t, errors, policy)
        n = t.shape[0]
        out = np.empty((n, 7))
        stamps = t.copy()
        valid = np.ones(n, dtype=bool)
        if target_frame == source_frame:
            # The single lookup validates nothing here; time 0 is stamped with the frame's
            # newest sample: ask it once.
            out[:] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
            zero = t == 0
            if zero.any():
                latest = self.lookup_transform(target_frame, source_frame, _LATEST)
                stamps[zero] = latest.header.stamp.ns
            return TransformArray(stamps, out[:, :3], out[:, 3:], target_frame, source_frame)
        ok = np.empty(n, dtype=np.int8)
        answered = lookup_rows(self, target_frame, source_frame, t, out, stamps, ok)
        if answered < 0:
            # An invalid or unknown frame id: the single lookup raises tf2's exception.
            self.lookup_transform(target_frame, source_frame, Time.from_ns(int(t[0]) if n else 0))
            raise AssertionError("lookup_transform accepted an id batch_lookup refused")
        if answered == n:
            return TransformArray(
                stamps, out[:, :3], out[:, 3:], target_frame, source_frame, valid
            )
        bad = np.flatnonzero(ok == 0)
        if errors == "raise":
            self.lookup_transform(target_frame, source_frame, Time.from_ns(int(t[bad[0]])))
            raise AssertionError("lookup_transform answered a time the walk could not")
        # Each masked row's reason: the single lookup's exception (once per distinct time).
        failed: dict[int, TransformException] = {}
        for i, found in single_lookups(
            self.lookup_transform, target_frame, source_frame, t, bad.tolist()
        ):
            if isinstance(found, TransformException):
                failed[i] = found
            else:  # (the kernel and the single walk agree: not reached)
                (x, y, z), (qx, qy, qz, qw) = found.transform
                out[i] = (x, y, z, qx, qy, qz, qw)
                stamps[i] = found.header.stamp.ns
        rows = list(failed)
        out[rows] = math.nan
        valid[rows] = False
        return TransformArray(
            stamps, out[:, :3], out[:, 3:], target_frame, source_frame, valid, errors=failed
        )

    def _policy_rows(
        self,
        target_frame: str,
        source_frame: str,
        t: npt.NDArray[np.int64],
        errors: Errors,
        policy: LookupPolicy,
    ) -> TransformArray:
        """``lookup_transforms`` under a non-exact policy: the core's policy walk per row."""
        args = policy_args(policy)
        n = t.shape[0]
        out = np.full((n, 7), math.nan)
        stamps = t.copy()
        valid = np.ones(n, dtype=bool)
        reports: list[PolicyReport | None] = [None] * n
        failed: dict[int, TransformException] = {}
        query = self._query_policy
        for i, ns in enumerate(t.tolist()):
            found = query(target_frame, source_frame, Time.from_ns(ns), args)
            if isinstance(found, PolicyResult):
                ts, reports[i] = found
                (x, y, z), (qx, qy, qz, qw) = ts.transform
                out[i] = (x, y, z, qx, qy, qz, qw)
                stamps[i] = ts.header.stamp.ns
                continue
            failure = self._failure("lookupTransform", target_frame, source_frame, found)
            if errors == "raise" or found[0] in (INVALID_ARGUMENT, UNKNOWN_FRAME):
                raise failure
            valid[i] = False
            failed[i] = failure
        return TransformArray(
            stamps, out[:, :3], out[:, 3:], target_frame, source_frame, valid, reports=reports,
            errors=failed,
        )

    def lookup_transforms_full(
        self,
        target_frame: str,
        target_times: TimesLike,
        source_frame: str,
        source_times: TimesLike,
        fixed_frame: str,
        *,
        errors: Errors = "raise",
        policy: LookupPolicy | None = None,
    ) -> TransformArray:
        """``lookup_transform_full`` (time travel through ``fixed_frame``) row by row.

        ``target_times`` and ``source_times`` are ``(N,)`` int64 ns (or Times); either may
        be a single time, broadcast to the other's N. Row i is ``lookup(target <- fixed @
        target_times[i]) o lookup(fixed <- source @ source_times[i])`` through normalised
        rotations, exactly as :meth:`lookup_transform_full` computes it
        (:func:`~tfbus.core.batch.compose_rows`); its stamp is the second leg's.

        Raises:
            InvalidArgumentException, LookupException: a frame id is invalid or unknown
                (validated in the order target, source, fixed).
            ConnectivityException, ExtrapolationException: as the single call for the
                first failing row (source leg first), unless ``errors="mask"``.
            ValueError: the time arrays have different lengths, or are malformed.

        ``policy`` as in :meth:`lookup_transforms`, applied to both legs: a row's report
        lists the first leg's links then the second's (``lookup_transform_full``'s), its
        largest delta over both.
        """
        check_errors(errors)
        frames = (target_frame, source_frame, fixed_frame)
        if not all(self.invalid_frame_id(f) is None and self.frame_exists(f) for f in frames):
            # The single call validates the three ids first, in this order: let it raise.
            self.lookup_transform_full(target_frame, _LATEST, source_frame, _LATEST, fixed_frame)
        tt = as_times(target_times)
        st = as_times(source_times)
        n = max(tt.shape[0], st.shape[0])
        tt, st = as_times(tt, n), as_times(st, n)
        leg1 = self.lookup_transforms(fixed_frame, source_frame, st, errors="mask", policy=policy)
        leg2 = self.lookup_transforms(target_frame, fixed_frame, tt, errors="mask", policy=policy)
        if errors == "raise":
            # The single call looks up leg 1 then leg 2 per time: the first failing row
            # decides, and within it the source leg.
            bad = np.flatnonzero(~(leg1.valid & leg2.valid))
            if bad.size:
                i = int(bad[0])
                self.lookup_transform_full(
                    target_frame,
                    Time.from_ns(int(tt[i])),
                    source_frame,
                    Time.from_ns(int(st[i])),
                    fixed_frame,
                    policy=policy,
                )
                raise AssertionError("lookup_transform_full did not raise")  # pragma: no cover
        rows = compose_rows(leg2, leg1)
        if leg1.reports is None or leg2.reports is None:
            return rows
        reports = [
            None
            if a is None or b is None
            else PolicyReport(
                a.frames + b.frames,
                a.stamps_ns + b.stamps_ns,
                max(a.max_abs_delta_ns, b.max_abs_delta_ns),
            )
            for a, b in zip(leg1.reports, leg2.reports, strict=True)
        ]
        return TransformArray(
            rows.stamps,
            rows.translations,
            rows.rotations,
            rows.frame_id,
            rows.child_frame_id,
            rows.valid,
            reports=reports,
            errors=rows._errors,
        )

    def transform_points(
        self,
        points: npt.ArrayLike,
        target_frame: str,
        source_frame: str,
        times: TimesLike,
        *,
        errors: Errors = "raise",
    ) -> npt.NDArray[np.float64]:
        """Map each point of ``points`` from ``source_frame`` into ``target_frame`` at its
        own time (per-beam projection, lidar de-skewing).

        Args:
            points: ``(N, 3)`` metres in ``source_frame``.
            target_frame: frame to express the points in.
            source_frame: frame the points are in.
            times: ``(N,) int64`` ns (or one time for all points).
            errors: ``"mask"`` gives NaN rows for points whose time cannot be answered.

        Returns:
            ``(N, 3) float64`` metres: row i is ``quatRotate(q_i, p_i) + t_i`` with
            ``(t_i, q_i) = lookup_transform(target_frame, source_frame, times[i])``.

        Raises:
            ValueError: ``points`` is not ``(N, 3)`` or ``times`` does not match.
            TransformException subclasses: as :meth:`lookup_transforms`.
        """
        p = np.asarray(points, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 3:
            raise ValueError(f"points must have shape (N, 3), got {p.shape}")
        tf = self.lookup_transforms(
            target_frame, source_frame, as_times(times, p.shape[0]), errors=errors
        )
        return tf.apply(p)

    def chain_frames(
        self, target_frame: str, source_frame: str, time: Time = _LATEST
    ) -> list[str]:
        """The frame ids an answer for ``lookup_transform(target_frame, source_frame,
        time)`` depends on, now and as data arrives (like tf2's ``_chainAsVector``): both
        ids, their ancestors by each link's newest parent and, for ``time`` other than 0,
        by the parent valid at ``time`` (a re-parented link), at most
        ``MAX_GRAPH_DEPTH + 1`` per chain. Unknown ids are included as given.

        Returns:
            Frame ids, no duplicates, in discovery order.
        """
        return self._chain(target_frame, source_frame, time)

    @overload
    def lookup_transform_full(
        self,
        target_frame: str,
        target_time: Time,
        source_frame: str,
        source_time: Time,
        fixed_frame: str,
        *,
        policy: Exact | None = None,
    ) -> TransformStamped: ...

    @overload
    def lookup_transform_full(
        self,
        target_frame: str,
        target_time: Time,
        source_frame: str,
        source_time: Time,
        fixed_frame: str,
        *,
        policy: Nearest | Clamp | Previous | Window,
    ) -> PolicyResult: ...

    def lookup_transform_full(
        self,
        target_frame: str,
        target_time: Time,
        source_frame: str,
        source_time: Time,
        fixed_frame: str,
        *,
        policy: LookupPolicy | None = None,
    ) -> TransformStamped | PolicyResult:
        """Time travel (tf2 ``lookupTransform`` with a fixed frame): where data in
        ``source_frame`` at ``source_time`` is, in ``target_frame`` at ``target_time``,
        assuming ``fixed_frame`` does not move.

        Computed as ``lookup(target ← fixed @ target_time) ∘ lookup(fixed ← source @
        source_time)`` through rotation matrices, as tf2 does, so the returned rotation is
        unit-norm (``compose_full`` of the core). ``header.stamp`` is the stamp of
        the second leg (target at target_time).

        Raises:
            InvalidArgumentException, LookupException, ConnectivityException,
            ExtrapolationException: as :meth:`lookup_transform`; ids are validated in the
                order target, source, fixed, before anything else.

        ``policy`` as in :meth:`lookup_transform`, applied to both legs; a non-exact
        policy returns a :class:`~tfbus.core.policy.PolicyResult` whose report lists the
        first leg's links (source up to fixed, against ``source_time``) then the second's
        (fixed to target, against ``target_time``), its largest delta over both.
        """
        self._validate("lookupTransform argument target_frame", target_frame)
        self._validate("lookupTransform argument source_frame", source_frame)
        self._validate("lookupTransform argument fixed_frame", fixed_frame)
        if policy is not None and type(policy) is not Exact:
            r1 = self._lookup_policy(fixed_frame, source_frame, source_time, policy)
            r2 = self._lookup_policy(target_frame, fixed_frame, target_time, policy)
            ts = self._compose_legs(r1.transform, r2.transform, target_frame, source_frame)
            a, b = r1.report, r2.report
            report = PolicyReport(
                a.frames + b.frames,
                a.stamps_ns + b.stamps_ns,
                max(a.max_abs_delta_ns, b.max_abs_delta_ns),
            )
            return PolicyResult(ts, report)
        leg1 = self.lookup_transform(fixed_frame, source_frame, source_time)
        leg2 = self.lookup_transform(target_frame, fixed_frame, target_time)
        return self._compose_legs(leg1, leg2, target_frame, source_frame)

    @staticmethod
    def _compose_legs(
        leg1: TransformStamped, leg2: TransformStamped, target_frame: str, source_frame: str
    ) -> TransformStamped:
        """``leg2 ∘ leg1`` through normalised rotations (``compose_full``), stamped
        with leg2's time, as tf2's fixed-frame lookup builds it."""
        (t1, q1), (t2, q2) = leg1.transform, leg2.transform
        v = compose_full((*t2, *q2), (*t1, *q1))
        return TransformStamped(
            Header(leg2.header.stamp, target_frame),
            source_frame,
            Transform(Vector3(*v[:3]), Quaternion(*v[3:])),
        )

    def can_transform(
        self,
        target_frame: str,
        source_frame: str,
        time: Time,
        return_debug_tuple: bool = False,
        *,
        policy: LookupPolicy | None = None,
    ) -> bool | tuple[bool, str]:
        """Whether :meth:`lookup_transform` would succeed (tf2 ``canTransform``). Never
        raises for missing data or bad ids.

        ``policy`` (:mod:`tfbus.core.policy`): whether :meth:`lookup_transform` with that
        policy would succeed (``None`` or ``Exact()``: tf2's rule).

        Returns:
            A bool, or ``(bool, tf2's error message)`` when ``return_debug_tuple`` is
            true (tf2_ros convention). The message is empty on success and for empty or
            '/'-prefixed ids; under a policy it is the error that lookup would raise.

        Raises:
            TypeError: ``policy`` is not a lookup policy, or ``time`` not a Time.
        """
        if policy is not None and type(policy) is not Exact:
            found = self._policy_query(target_frame, source_frame, time, policy)
            if isinstance(found, PolicyResult):
                ok, msg = True, ""
            else:
                ok, msg = self._cannot(target_frame, source_frame, found)
        else:
            ok, msg = self._can_transform(target_frame, source_frame, time)
        return (ok, msg) if return_debug_tuple else ok

    def _can_transform(self, target_frame: str, source_frame: str, time: Time) -> tuple[
        bool, str
    ]:
        try:
            out = self._query(target_frame, source_frame, time)
        except AttributeError as err:  # (no cost on the way through)
            raise not_a_time(time, err) from None
        if isinstance(out, TransformStamped):
            return True, ""
        return self._cannot(target_frame, source_frame, out)

    def _cannot(
        self, target_frame: str, source_frame: str, out: tuple[int, ...]
    ) -> tuple[bool, str]:
        """``can_transform``'s ``(False, message)`` for a failed query."""
        code = out[0]
        if code in (INVALID_ARGUMENT, UNKNOWN_FRAME):
            # tf2 canTransform: empty / '/'-prefixed ids first (no message), then both
            # unknown ids named.
            for frame in (target_frame, source_frame):
                if not isinstance(frame, str) or not frame or frame[0] == "/":
                    return False, ""
            msgs = []
            if not self.frame_exists(target_frame):
                msgs.append(f"canTransform: target_frame {target_frame} does not exist.")
            if not self.frame_exists(source_frame):
                msgs.append(f"canTransform: source_frame {source_frame} does not exist.")
            return False, " ".join(msgs)
        return False, str(self._failure("lookupTransform", target_frame, source_frame, out))

    def can_transform_full(
        self,
        target_frame: str,
        target_time: Time,
        source_frame: str,
        source_time: Time,
        fixed_frame: str,
        return_debug_tuple: bool = False,
    ) -> bool | tuple[bool, str]:
        """Whether :meth:`lookup_transform_full` would succeed (tf2 ``canTransform`` with
        a fixed frame). Never raises for missing data or bad ids.

        The debug message reproduces tf2 0.7.6 exactly, including its bug: an unknown
        fixed frame alone gives an empty message, and ``" fixed_frame: Fdoes not exist."``
        is appended when the *source* is unknown.
        """
        ok, msg = self._can_transform_full(
            target_frame, target_time, source_frame, source_time, fixed_frame
        )
        return (ok, msg) if return_debug_tuple else ok

    def _can_transform_full(
        self, target: str, target_t: Time, source: str, source_t: Time, fixed: str
    ) -> tuple[bool, str]:
        for frame in (target, source, fixed):
            if not isinstance(frame, str) or not frame or frame[0] == "/":
                return False, ""
        known = self.frame_exists
        if not (known(target) and known(source) and known(fixed)):
            msg = ""
            if not known(target):
                msg += f"canTransform: target_frame {target} does not exist."
            if not known(source):
                if not known(target):
                    msg += " "
                msg += f"canTransform: source_frame {source} does not exist."
                msg += f" fixed_frame: {fixed}does not exist."
            return False, msg
        ok, msg = self._can_transform(target, fixed, target_t)
        if not ok:
            return ok, msg
        return self._can_transform(fixed, source, source_t)

    def get_latest_common_time(self, target_frame: str, source_frame: str) -> Time:
        """The latest time at which the whole path between the two frames has data — what
        ``Time(0)`` resolves to in a lookup (tf2 ``getLatestCommonTime``). ``Time(0)`` if
        only static links (or links stamped 0) lie between them.

        Raises:
            InvalidArgumentException: a frame id is empty or starts with '/'.
            LookupException: a frame id is unknown.
            TransformException: the frames are not connected, or the path has a loop
                (tf2_py raises the base class here).
        """
        self._validate("get_latest_common_time", target_frame)
        self._validate("get_latest_common_time", source_frame)
        err, t = self.common_time(target_frame, source_frame)
        if err == LOOKUP_ERROR:
            raise TransformException(str(self._failure("", target_frame, source_frame, (err,))))
        if err:
            raise TransformException(
                str(self._failure("", target_frame, source_frame, (CONNECTIVITY_ERROR,)))
            )
        return Time.from_ns(t)

    # ------------------------------------------------------------------ introspection

    parent_of = _PARENT_OF
    """Not public: the core's ``parent_of(frame_id, time_ns)`` goes by tf2's name,
    :meth:`get_parent`; reading this attribute raises AttributeError saying so."""

    def __dir__(self) -> list[str]:
        """``dir()`` without the core's names that go by another public name here."""
        return [name for name in super().__dir__() if name != "parent_of"]

    def get_parent(self, frame_id: str, time: Time = _LATEST) -> str | None:
        """The parent of ``frame_id`` at ``time`` (0 = latest), or None for a root, an
        unknown frame or a time the link has no data for (tf2 ``BufferCore::_getParent``).

        Args:
            frame_id: the child frame.
            time: a :class:`~tfbus.time.Time`; ``Time(0)`` is the link's newest data.

        Raises:
            TypeError: ``time`` is not a Time (an int of nanoseconds is refused, not
                taken as seconds or ns).
        """
        if not isinstance(time, Time):
            raise TypeError(
                f"get_parent: time must be a tfbus Time (Time(0) = latest), got "
                f"{type(time).__name__} {time!r}"
            )
        parent: str | None = _PARENT_OF.call(self, frame_id, time.ns)
        return parent

    def all_frames_as_string(self) -> str:
        """One line ``Frame X exists with parent Y.`` per frame that has a link, in
        registration order (tf2 ``allFramesAsString``)."""
        return frames_as_string(self.frame_info())

    def all_frames_as_yaml(self, current_time: Time | None = None) -> str:
        """The frame tree as YAML in tf2's format (``allFramesAsYAML``): per child frame
        its ``parent``, ``broadcaster`` (authority), ``rate`` (Hz, samples / span),
        ``most_recent_transform``, ``oldest_transform``, ``buffer_length`` (seconds,
        3 decimals) and, when ``current_time`` is given, ``transform_delay``.

        tf2's text, character for character, for ordinary ids; an id YAML would misread
        (``a: b``, ``#x``, ``true``, quotes, line breaks, ...) is quoted, so the text is
        always valid YAML that reads back every id unchanged.
        """
        return frames_as_yaml(self.frame_info(), current_time)

    def frame_info(self) -> Iterator[FrameInfo]:
        """Per linked frame, in registration order, a :class:`FrameInfo` ``(child,
        parent, authority, is_static, samples, oldest_ns, newest_ns)`` — the data behind
        ``all_frames_as_string`` and ``all_frames_as_yaml``, for tools. The parent of an
        emptied link is ``NO_PARENT``."""
        return map(FrameInfo._make, self.link_info())

    def __repr__(self) -> str:
        return (
            f"BufferCore(cache_time={self.cache_time_ns / 1e9:g}, "
            f"frames={len(self.get_frame_names())})"
        )

    # ------------------------------------------------------------------ velocity, chain

    def lookup_velocity(
        self,
        tracking_frame: str,
        observation_frame: str,
        time: Time,
        averaging_interval: Duration | float,
        *,
        method: str = "tf2",
    ) -> VelocityStamped:
        """The velocity of ``tracking_frame`` relative to ``observation_frame``, expressed
        in ``observation_frame`` about the tracking frame's origin, averaged over
        ``averaging_interval`` (seconds or a Duration, > 0) around ``time`` (0: the latest
        common time). tf2 ``BufferCore::lookupVelocity`` (ROS 2) / ``tf::Transformer::
        lookupTwist`` (ROS 1); see :mod:`tfbus.core.velocity` for the formula, and for why
        ``method="tf2"`` (the default, tf2's numbers) is not the physical velocity of a
        rotating frame and what ``method="origin"`` returns instead.

        Returns:
            VelocityStamped (m/s, rad/s) with ``header.frame_id == observation_frame``,
            ``body_frame_id == tracking_frame``.

        Raises:
            InvalidArgumentException: a bad ``averaging_interval``, ``time`` or
                ``method`` (the message names the argument and value), or a bad frame id.
            LookupException, ConnectivityException, ExtrapolationException: as
                :meth:`lookup_transform`, for the window's ends.
        """
        return _lookup_velocity(
            self, tracking_frame, observation_frame, observation_frame, (0.0, 0.0, 0.0),
            tracking_frame, time, averaging_interval, method,
        )

    def lookup_velocity_full(
        self,
        tracking_frame: str,
        observation_frame: str,
        reference_frame: str,
        reference_point: Vector3 | tuple[float, float, float],
        reference_point_frame: str,
        time: Time,
        averaging_interval: Duration | float,
        *,
        method: str = "tf2",
    ) -> VelocityStamped:
        """:meth:`lookup_velocity` expressed in ``reference_frame`` about
        ``reference_point`` (x, y, z metres in ``reference_point_frame``), tf2's argument
        order (ROS 2 ``lookupVelocity`` with seven arguments, ROS 1 ``lookupTwist``).

        Returns:
            VelocityStamped with ``header.frame_id == reference_frame``.

        Raises:
            as :meth:`lookup_velocity`; InvalidArgumentException also for a
            ``reference_point`` that is not 3 finite numbers.
        """
        return _lookup_velocity(
            self, tracking_frame, observation_frame, reference_frame, reference_point,
            reference_point_frame, time, averaging_interval, method,
        )

    def frame_path(self, source_frame: str, target_frame: str) -> list[str] | None:
        """The frames from ``source_frame`` up to the lowest common ancestor and down to
        ``target_frame`` by each link's newest parent (:func:`frame_path`); None when
        they are not connected (two trees, a loop or an unknown id).

        Returns:
            Frame ids, ``[source_frame]`` when the two ids are one.
        """
        return frame_path({info.child: info.parent for info in self.frame_info()},
                          source_frame, target_frame)

    def all_frames_as_dot(self, current_time: Time | None = None) -> str:
        """The frame tree as a Graphviz ``digraph`` in tf2 0.7.6's text
        (``BufferCore::_allFramesAsDot``, what view_frames draws): an edge per link with
        its broadcaster, rate (Hz), newest stamp and buffer length (seconds); with a
        ``current_time`` > 0, each link's age and a legend pointing at the roots."""
        seconds = 0.0 if current_time is None else current_time.ns / 1e9
        return frames_as_dot(self.get_frame_names(), self.frame_info(), seconds)

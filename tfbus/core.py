"""BufferCore: the frame graph and its lookups — synchronous and sans-I/O.

This is tf2's ``BufferCore`` (ROS 1 geometry2 0.7.6, ``tf2/src/buffer_core.cpp``)
re-implemented with the same semantics (API and messages here; storage, insert and the
walk compiled in ``tfbus/_ccore.pyx``), checked against vectors recorded from the real
tf2 (``tests/data/public.jsonl.gz`` and ``tf2_regressions.jsonl``):

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

import enum
import logging
import math
import time as _wallclock
from collections.abc import Iterable
from typing import Final, NamedTuple

from tfbus._ccore import (
    CONNECTIVITY_ERROR,
    EXTRAPOLATION_ERROR,
    LOOKUP_ERROR,
    MAX_GRAPH_DEPTH,
    NO_ERROR,
    OLD_DATA,
    CoreBase,
)
from tfbus._tf2math import Tf7
from tfbus.batch import BatchLookupMixin
from tfbus.errors import (
    ConnectivityException,
    ExtrapolationException,
    InvalidArgumentException,
    LookupException,
    TransformException,
)
from tfbus.messages import Header, Quaternion, Transform, TransformStamped, Vector3
from tfbus.time import Duration, Time

__all__ = ["MAX_GRAPH_DEPTH", "BatchResult", "BufferCore", "SetResult"]

logger = logging.getLogger("tfbus.core")

_MAX_MESSAGE: Final = 999  # extrapolation messages only (tf2 0.7.6, measured with tf2_py)

_LATEST: Final = Time(0)
_MEMO_SIZE: Final = 64  # small: a larger memo costs a never-repeated query ~1 µs of churn

_ERRORS: Final[dict[int, type[TransformException]]] = {
    LOOKUP_ERROR: LookupException,
    CONNECTIVITY_ERROR: ConnectivityException,
    EXTRAPOLATION_ERROR: ExtrapolationException,
}


class SetResult(enum.Enum):
    """What ``BufferCore.insert_transform`` did with a transform."""

    STORED = "stored"
    OLD_DATA = "TF_OLD_DATA"
    """Refused: older than the link's newest stamp minus ``cache_time``."""
    REPEATED_DATA = "TF_REPEATED_DATA"
    """Refused: the link already has a sample with this stamp (the first one wins)."""


_RESULTS: Final = (SetResult.STORED, SetResult.OLD_DATA, SetResult.REPEATED_DATA)


class BatchResult(NamedTuple):
    """What :meth:`BufferCore.set_transforms` did with a batch of transforms."""

    stored: int
    """How many were stored."""
    refused: int
    """How many the caches refused (TF_OLD_DATA, TF_REPEATED_DATA; logged)."""
    errors: list[tuple[int, Exception]]
    """``(index in the batch, exception)`` for each item that was not stored because it
    is invalid (:class:`~tfbus.errors.InvalidArgumentException`) or is not a well-formed
    :class:`~tfbus.messages.TransformStamped` (TypeError, ValueError, OverflowError)."""


class _RateLimitedWarning:
    """Log a warning at most once per ``period`` seconds per key, counting the rest."""

    def __init__(self, period: float = 5.0) -> None:
        self.period = period
        self._last: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}

    def __call__(self, key: str, message: str) -> None:
        now = _wallclock.monotonic()
        last = self._last.get(key)
        if last is not None and now - last < self.period:
            self._suppressed[key] = self._suppressed.get(key, 0) + 1
            return
        self._last[key] = now
        n = self._suppressed.pop(key, 0)
        logger.warning("%s%s", message, f" ({n} similar messages suppressed)" if n else "")


def _strip_slash(frame_id: str) -> str:
    return frame_id[1:] if frame_id.startswith("/") else frame_id


def _cap(message: str) -> str:
    """tf2 0.7.6 truncates extrapolation messages (only those) to 999 characters."""
    return message[:_MAX_MESSAGE]


def _seconds_to_ns(value: float | Duration) -> int:
    if isinstance(value, Duration):
        return value.ns
    return round(value * 1_000_000_000)


class BufferCore(BatchLookupMixin, CoreBase):
    """tf2's transform buffer: stores stamped transforms per link and answers lookups.

    Args:
        cache_time: how long to keep each dynamic link's history, seconds (float) or a
            :class:`~tfbus.time.Duration`. Expiry happens per link on insert, relative to
            that link's newest stamp, exactly as in tf2 (no wall clock is involved).

    Frame ids are arbitrary strings compared exactly. ``set_transform`` strips one
    leading ``/`` (tf2 ``stripSlash``); queries reject ids that start with ``/``.
    Not thread-safe: use it from one thread (or one event loop), as tfbus does.

    Storage, insert and the walk are compiled (:mod:`tfbus._ccore`, Cython); this class
    holds the API, validation of queries and tf2's messages.
    """

    def __init__(self, cache_time: float | Duration = 10.0) -> None:
        self.cache_time_ns: int = _seconds_to_ns(cache_time)
        if self.cache_time_ns < 0:
            raise ValueError(f"cache_time must be >= 0, got {cache_time!r}")
        # CoreBase holds the frame table: _frame_ids, _frame_names, _caches (frame 0 is
        # tf2's reserved NO_PARENT; it may get a cache of its own, a tf2 quirk) and
        # _authority, and bumps _generation on every insert attempt.
        self._set_cache_time_ns(self.cache_time_ns)
        self._warn = _RateLimitedWarning()
        # Exact memo of successful lookup_transform results, keyed by (target, source,
        # time ns). Any insert attempt or clear() bumps _generation, which empties it, so
        # it never serves data older than the buffer's state.
        self._memo: dict[tuple[str, str, int], TransformStamped] = {}
        self._memo_generation = 0

    # ------------------------------------------------------------------ inserting

    @property
    def cache_time(self) -> Duration:
        """The history kept per dynamic link."""
        return Duration.from_ns(self.cache_time_ns)

    def set_transform(self, transform: TransformStamped, authority: str = "default") -> bool:
        """Store a dynamic transform (tf2 ``BufferCore::setTransform``).

        Args:
            transform: ``header.frame_id`` is the parent, ``child_frame_id`` the child,
                ``header.stamp`` the time; translation in metres, rotation (x, y, z, w).
            authority: who sent it (shown by ``all_frames_as_yaml``).

        Returns:
            True when stored; False when the link's cache refused it — TF_OLD_DATA (older
            than its newest stamp minus ``cache_time``) or TF_REPEATED_DATA (a sample
            with this stamp exists) — which is logged as a rate-limited warning.

        Raises:
            InvalidArgumentException: malformed transform — self transform, empty
                frame id, NaN, ±Inf in the translation, or a quaternion whose squared
                norm is not within 0.01 of 1. The message names each field and value;
                ``.codes`` holds tf2's ``TF_*`` codes in tf2's order. Nothing is stored.
        """
        return self._insert(transform, authority, False) is SetResult.STORED

    def set_transform_static(
        self, transform: TransformStamped, authority: str = "default"
    ) -> bool:
        """Store a static transform: valid at all times, overwritten by every later send
        (tf2 ``setTransform(..., is_static=true)``). Whether a link is static is fixed by
        its first accepted transform, as in tf2.

        Returns and raises as :meth:`set_transform`.
        """
        return self._insert(transform, authority, True) is SetResult.STORED

    def insert_transform(
        self, transform: TransformStamped, authority: str = "default", is_static: bool = False
    ) -> SetResult:
        """Like :meth:`set_transform` / :meth:`set_transform_static`, but tells why a
        transform was refused. Raises as :meth:`set_transform`."""
        return self._insert(transform, authority, is_static)

    def _insert(self, ts: TransformStamped, authority: str, is_static: bool) -> SetResult:
        return _RESULTS[self._insert_code(ts, authority, is_static)]

    def set_transforms(
        self,
        transforms: Iterable[TransformStamped],
        authority: str = "default",
        is_static: bool = False,
    ) -> BatchResult:
        """Store a batch of transforms (a ``TFMessage``'s worth) in one call: what the
        listener uses, several times faster per transform than :meth:`set_transform`.

        Each item is handled exactly as :meth:`set_transform` (or
        :meth:`set_transform_static` when ``is_static``) would, in order; an invalid or
        malformed item is reported in ``errors`` instead of raising, and never stops the
        items after it. Refusals (TF_OLD_DATA, TF_REPEATED_DATA) are logged, rate-limited.
        """
        return BatchResult(*self._insert_many(transforms, authority, is_static, None))

    def _refused(self, code: int, child: str, stamp: int, authority: str) -> None:
        """Log a refusal by the cache (rate-limited), in tf2's words."""
        if code == OLD_DATA:
            self._warn(
                "TF_OLD_DATA",
                "TF_OLD_DATA ignoring data from the past (Possible reasons are listed at "
                "http://wiki.ros.org/tf/Errors%20explained) for frame "
                f"{child} at time {stamp / 1e9:f} according to authority {authority}",
            )
        else:
            self._warn(
                "TF_REPEATED_DATA",
                f"TF_REPEATED_DATA ignoring data with redundant timestamp for frame {child} "
                f"at time {stamp / 1e9:f} according to authority {authority}",
            )

    def _reject(self, parent: str, child: str, values: Tf7, authority: str) -> None:
        """Raise InvalidArgumentException listing every problem in tf2's order
        (``BufferCore::setTransformImpl``) plus tfbus's TF_INF_INPUT."""
        codes: list[str] = []
        problems: list[str] = []
        if child == parent:
            codes.append("TF_SELF_TRANSFORM")
            problems.append(f"header.frame_id and child_frame_id are the same ({child!r})")
        if not child:
            codes.append("TF_NO_CHILD_FRAME_ID")
            problems.append("child_frame_id is empty")
        if not parent:
            codes.append("TF_NO_FRAME_ID")
            problems.append("header.frame_id is empty")
        fields = (
            "transform.translation.x",
            "transform.translation.y",
            "transform.translation.z",
            "transform.rotation.x",
            "transform.rotation.y",
            "transform.rotation.z",
            "transform.rotation.w",
        )
        nans = [f"{name} = nan" for name, v in zip(fields, values, strict=True) if math.isnan(v)]
        if nans:
            codes.append("TF_NAN_INPUT")
            problems.extend(nans)
        infs = [
            f"{name} = {v}" for name, v in zip(fields[:3], values[:3], strict=True) if math.isinf(v)
        ]
        if infs:
            codes.append("TF_INF_INPUT")
            problems.extend(infs)
        qx, qy, qz, qw = values[3:]
        # tf2's order (setTransformImpl: w² + x² + y² + z²): it decides cases at the limit.
        norm2 = qw * qw + qx * qx + qy * qy + qz * qz
        if not abs(norm2 - 1.0) < 0.01:
            codes.append("TF_DENORMALIZED_QUATERNION")
            problems.append(
                f"transform.rotation = ({qx}, {qy}, {qz}, {qw}) has squared norm {norm2}, "
                "not within 0.01 of 1"
            )
        raise InvalidArgumentException(
            f"Invalid transform for child_frame_id {child!r} from authority {authority!r}: "
            + "; ".join(problems),
            codes=tuple(codes),
        )

    def clear(self) -> None:
        """Drop all dynamic data; static transforms and known frame ids stay
        (tf2 ``BufferCore::clear``).

        As in tf2, the reserved frame 0 (``NO_PARENT``) is skipped: a link stored with
        child ``"NO_PARENT"`` keeps its samples."""
        self._generation += 1
        for cache in self._caches[1:]:
            if cache is not None:
                cache.clear()

    # ------------------------------------------------------------------ validation

    def _validate(self, function: str, frame_id: str) -> int:
        """tf2 ``validateFrameId``: id of a known frame, else raise."""
        fid = self._frame_ids.get(frame_id)
        if fid and frame_id[0] != "/":  # known, not NO_PARENT (0), not "/x" (from "//x")
            return fid
        if not frame_id:
            raise InvalidArgumentException(
                f"Invalid argument passed to {function} in tf2 frame_ids cannot be empty"
            )
        if frame_id[0] == "/":
            raise InvalidArgumentException(
                f'Invalid argument "{frame_id}" passed to {function} in tf2 frame_ids '
                "cannot start with a '/' like: "
            )
        raise LookupException(f'"{frame_id}" passed to {function} does not exist. ')

    # ------------------------------------------------------------------ the walk

    def _common_time(self, target_id: int, source_id: int) -> tuple[int, int | str]:
        """tf2 ``getLatestCommonTime``: ``(NO_ERROR, time ns)`` or ``(error, message)``."""
        err, t = self._ccommon_time(target_id, source_id)
        if err == NO_ERROR:
            return err, t
        if err == LOOKUP_ERROR:
            return err, self._loop_message()
        return err, self._connectivity_message(source_id, target_id)

    def _walk(self, target_id: int, source_id: int, time: int) -> tuple[int, Tf7 | str, int]:
        """tf2 ``walkToTopParent`` with ``TransformAccum`` (compiled, ``CoreBase._cwalk``).

        Returns ``(NO_ERROR, transform, time used)`` or ``(error code, message, 0)``.
        The transform maps source coordinates into target coordinates.
        """
        err, payload, used = self._cwalk(target_id, source_id, time)
        if err == NO_ERROR:
            return err, payload, used  # type: ignore[return-value]
        if err == EXTRAPOLATION_ERROR:
            cache = self._caches[payload]  # type: ignore[index]
            detail = cache.gather(used) if cache is not None else ""
            detail = detail if isinstance(detail, str) else ""  # a link to NO_PARENT
            return err, self._extrapolation_message(detail, source_id, target_id), 0
        if err == LOOKUP_ERROR:
            return err, self._loop_message(), 0
        return err, self._connectivity_message(source_id, target_id), 0

    # ------------------------------------------------------------------ messages

    def _connectivity_message(self, source_id: int, target_id: int) -> str:
        names = self._frame_names
        return (
            f"Could not find a connection between '{names[target_id]}' and "
            f"'{names[source_id]}' because they are not part of the same tree."
            "Tf has two or more unconnected trees."
        )

    def _extrapolation_message(self, detail: str, source_id: int, target_id: int) -> str:
        names = self._frame_names
        return _cap(
            f"{detail}, when looking up transform from frame [{names[source_id]}] "
            f"to frame [{names[target_id]}]"
        )

    def _loop_message(self) -> str:
        return (
            "The tf tree is invalid because it contains a loop.\n"
            + self.all_frames_as_string()
            + "\n"
        )

    # ------------------------------------------------------------------ lookups

    def lookup_transform(
        self, target_frame: str, source_frame: str, time: Time
    ) -> TransformStamped:
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
            ExtrapolationException: a link on the path has no data at ``time``.

        Successful results are memoised until the next insert or ``clear()``, so repeating
        a query (many objects at one stamp, time 0 between updates) costs a dict lookup.
        """
        t = time.ns
        key = (target_frame, source_frame, t)
        if self._memo_generation == self._generation:
            hit = self._memo.get(key)
            if hit is not None:
                return hit
        else:
            self._memo.clear()
            self._memo_generation = self._generation
        if target_frame == source_frame:
            if t == 0:
                # tf2 stamps the identity with the frame's newest sample; an unknown id
                # maps to frame 0 (NO_PARENT), whose link exists only if "NO_PARENT" was
                # stored as a child (lookupFrameNumber / getFrame).
                cache = self._caches[self._frame_ids.get(target_frame, 0)]
                t = cache.latest_stamp() if cache is not None else 0
            return TransformStamped(
                Header(Time.from_ns(t), target_frame), source_frame, Transform()
            )
        target_id = self._validate("lookupTransform argument target_frame", target_frame)
        source_id = self._validate("lookupTransform argument source_frame", source_frame)
        err, result, used = self._walk(target_id, source_id, t)
        if err:
            raise _ERRORS[err](result)
        out = _stamped(target_frame, source_frame, result, used)  # type: ignore[arg-type]
        memo = self._memo
        if len(memo) >= _MEMO_SIZE:
            memo.clear()
        memo[key] = out
        return out

    def lookup_transform_full(
        self,
        target_frame: str,
        target_time: Time,
        source_frame: str,
        source_time: Time,
        fixed_frame: str,
    ) -> TransformStamped:
        """Time travel (tf2 ``lookupTransform`` with a fixed frame): where data in
        ``source_frame`` at ``source_time`` is, in ``target_frame`` at ``target_time``,
        assuming ``fixed_frame`` does not move.

        Computed as ``lookup(target ← fixed @ target_time) ∘ lookup(fixed ← source @
        source_time)`` through rotation matrices, as tf2 does, so the returned rotation is
        unit-norm. ``header.stamp`` is the stamp of the second leg (target at target_time).

        Raises:
            InvalidArgumentException, LookupException, ConnectivityException,
            ExtrapolationException: as :meth:`lookup_transform`; ids are validated in the
                order target, source, fixed, before anything else.
        """
        self._validate("lookupTransform argument target_frame", target_frame)
        self._validate("lookupTransform argument source_frame", source_frame)
        self._validate("lookupTransform argument fixed_frame", fixed_frame)
        leg1 = self.lookup_transform(fixed_frame, source_frame, source_time)
        leg2 = self.lookup_transform(target_frame, fixed_frame, target_time)
        (x1, y1, z1), q1 = leg1.transform
        (x2, y2, z2), (ax, ay, az, aw) = leg2.transform
        # tf2::Transform keeps a normalised rotation matrix: normalise both quaternions.
        n2 = math.sqrt(ax * ax + ay * ay + az * az + aw * aw)
        ax, ay, az, aw = ax / n2, ay / n2, az / n2, aw / n2
        bx, by, bz, bw = q1
        n1 = math.sqrt(bx * bx + by * by + bz * bz + bw * bw)
        bx, by, bz, bw = bx / n1, by / n1, bz / n1, bw / n1
        tx = aw * x1 + ay * z1 - az * y1
        ty = aw * y1 + az * x1 - ax * z1
        tz = aw * z1 + ax * y1 - ay * x1
        tw = -ax * x1 - ay * y1 - az * z1
        qx = aw * bx + ax * bw + ay * bz - az * by
        qy = aw * by + ay * bw + az * bx - ax * bz
        qz = aw * bz + az * bw + ax * by - ay * bx
        qw = aw * bw - ax * bx - ay * by - az * bz
        n = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
        result: Tf7 = (
            -tw * ax + tx * aw - ty * az + tz * ay + x2,
            -tw * ay + ty * aw - tz * ax + tx * az + y2,
            -tw * az + tz * aw - tx * ay + ty * ax + z2,
            qx / n,
            qy / n,
            qz / n,
            qw / n,
        )
        return _stamped(target_frame, source_frame, result, leg2.header.stamp.ns)

    def can_transform(
        self,
        target_frame: str,
        source_frame: str,
        time: Time,
        return_debug_tuple: bool = False,
    ) -> bool | tuple[bool, str]:
        """Whether :meth:`lookup_transform` would succeed (tf2 ``canTransform``). Never
        raises for missing data or bad ids.

        Returns:
            A bool, or ``(bool, tf2's error message)`` when ``return_debug_tuple`` is
            true (tf2_ros convention). The message is empty on success and for empty or
            '/'-prefixed ids.
        """
        ok, msg = self._can_transform(target_frame, source_frame, time.ns)
        return (ok, msg) if return_debug_tuple else ok

    def _can_transform(self, target_frame: str, source_frame: str, t: int) -> tuple[bool, str]:
        if target_frame == source_frame:
            return True, ""
        if not target_frame or target_frame[0] == "/":
            return False, ""
        if not source_frame or source_frame[0] == "/":
            return False, ""
        target_id = self._frame_ids.get(target_frame, 0)
        source_id = self._frame_ids.get(source_frame, 0)
        if target_id == 0 or source_id == 0:
            msgs = []
            if target_id == 0:
                msgs.append(f"canTransform: target_frame {target_frame} does not exist.")
            if source_id == 0:
                msgs.append(f"canTransform: source_frame {source_frame} does not exist.")
            return False, " ".join(msgs)
        err, result, _ = self._walk(target_id, source_id, t)
        return (False, result) if err else (True, "")  # type: ignore[return-value]

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
            target_frame, target_time.ns, source_frame, source_time.ns, fixed_frame
        )
        return (ok, msg) if return_debug_tuple else ok

    def _can_transform_full(
        self, target: str, target_t: int, source: str, source_t: int, fixed: str
    ) -> tuple[bool, str]:
        for frame in (target, source, fixed):
            if not frame or frame[0] == "/":
                return False, ""
        ids = self._frame_ids
        target_id, source_id, fixed_id = ids.get(target, 0), ids.get(source, 0), ids.get(fixed, 0)
        if target_id == 0 or source_id == 0 or fixed_id == 0:
            msg = ""
            if target_id == 0:
                msg += f"canTransform: target_frame {target} does not exist."
            if source_id == 0:
                if target_id == 0:
                    msg += " "
                msg += f"canTransform: source_frame {source} does not exist."
                msg += f" fixed_frame: {fixed}does not exist."
            return False, msg
        err, result, _ = self._walk(target_id, fixed_id, target_t)
        if err:
            return False, result  # type: ignore[return-value]
        err, result, _ = self._walk(fixed_id, source_id, source_t)
        if err:
            return False, result  # type: ignore[return-value]
        return True, ""

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
        target_id = self._validate("get_latest_common_time", target_frame)
        source_id = self._validate("get_latest_common_time", source_frame)
        err, result = self._common_time(target_id, source_id)
        if err:
            raise TransformException(result)
        return Time.from_ns(result)  # type: ignore[arg-type]

    # ------------------------------------------------------------------ introspection

    def get_frame_names(self) -> list[str]:
        """Every known frame id (children and parents), in registration order."""
        return self._frame_names[1:]

    def frame_exists(self, frame_id: str) -> bool:
        """Whether ``frame_id`` is known (tf2 ``_frameExists``)."""
        return self._frame_ids.get(frame_id, 0) != 0

    def get_parent(self, frame_id: str, time: Time = _LATEST) -> str | None:
        """The parent of ``frame_id`` at ``time`` (0 = latest), or None for a root, an
        unknown frame or a time the link has no data for (tf2 ``_getParent``)."""
        fid = self._frame_ids.get(frame_id, 0)
        cache = self._caches[fid] if fid else None
        if cache is None:
            return None
        r = cache.gather(time.ns)
        if isinstance(r, str) or r[0] == 0:
            return None
        return self._frame_names[r[0]]

    def all_frames_as_string(self) -> str:
        """One line ``Frame X exists with parent Y.`` per frame that has a link, in
        registration order (tf2 ``allFramesAsString``)."""
        return "".join(
            f"Frame {child} exists with parent {parent}.\n"
            for child, parent, *_ in self.frame_info()
        )

    def all_frames_as_yaml(self, current_time: Time | None = None) -> str:
        """The frame tree as YAML in tf2's format (``allFramesAsYAML``): per child frame
        its ``parent``, ``broadcaster`` (authority), ``rate`` (Hz, samples / span),
        ``most_recent_transform``, ``oldest_transform``, ``buffer_length`` (seconds,
        3 decimals) and, when ``current_time`` is given, ``transform_delay``."""
        out: list[str] = []
        for child, parent, authority, _static, samples, oldest, newest in self.frame_info():
            if not samples:  # a dynamic link emptied by clear(): tf2 lists only data
                continue
            rate = samples / max((newest - oldest) / 1e9, 0.0001)
            out.append(f"{child}: \n")
            out.append(f"  parent: '{parent}'\n")
            out.append(f"  broadcaster: '{authority}'\n")
            out.append(f"  rate: {rate:.3f}\n")
            out.append(f"  most_recent_transform: {newest / 1e9:.3f}\n")
            out.append(f"  oldest_transform: {oldest / 1e9:.3f}\n")
            if current_time is not None and current_time.ns > 0:
                out.append(f"  transform_delay: {(current_time.ns - newest) / 1e9:.3f}\n")
            out.append(f"  buffer_length: {(newest - oldest) / 1e9:.3f}\n")
        return "".join(out) if out else "[]"

    def frame_info(self) -> Iterable[tuple[str, str, str, bool, int, int, int]]:
        """Per linked frame, in registration order: ``(child, parent, authority, is_static,
        samples, oldest ns, newest ns)`` — the data behind ``all_frames_as_string`` and
        ``all_frames_as_yaml``, for tools. The parent of an emptied link is
        ``NO_PARENT``."""
        names = self._frame_names
        for fid in range(1, len(self._caches)):
            cache = self._caches[fid]
            if cache is None:
                continue
            r = cache.gather(0)
            parent = 0 if isinstance(r, str) else r[0]
            yield (
                names[fid],
                names[parent],
                self._authority.get(fid, "no recorded authority"),
                cache.is_static,
                len(cache),
                cache.oldest_stamp(),
                cache.latest_stamp(),
            )

    def _chain_ids(self, frame_id: str) -> list[int]:
        """Ids of ``frame_id`` and its ancestors by each link's newest sample (for waiter
        indexing; stops at loops)."""
        fid = self._frame_ids.get(frame_id, 0)
        out: list[int] = []
        seen: set[int] = set()
        while fid and fid not in seen:
            seen.add(fid)
            out.append(fid)
            cache = self._caches[fid]
            if cache is None:
                break
            fid = cache.latest()[1]
        return out

    def __repr__(self) -> str:
        return (
            f"BufferCore(cache_time={self.cache_time_ns / 1e9:g}, "
            f"frames={len(self._frame_names) - 1})"
        )


_new = tuple.__new__


def _stamped(target: str, source: str, v: Tf7, stamp_ns: int) -> TransformStamped:
    """Build the result message; ``tuple.__new__`` skips NamedTuple's Python-level
    ``__new__`` (half the cost of a lookup at depth 1)."""
    return _new(
        TransformStamped,
        (
            _new(Header, (Time.from_ns(stamp_ns), target)),
            source,
            _new(Transform, (_new(Vector3, v[:3]), _new(Quaternion, v[3:]))),
        ),
    )

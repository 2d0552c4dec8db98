"""The frame table and the walk in pure Python: :class:`CoreBase`, everything the
compiled :mod:`tfbus.core._ccore` exports, same behaviour.

The pure-Python core (this module with :mod:`~tfbus.core._pymath`,
:mod:`~tfbus.core._pycache` and :mod:`~tfbus.core._pybatch`) is loaded instead of the
compiled one when that was not built (no C compiler, or ``TFBUS_NO_EXTENSIONS=1`` at
install) or when ``TFBUS_PURE_PYTHON=1`` is set at import (:mod:`tfbus.core._select`
chooses; ``tfbus.core.COMPILED`` says which one is loaded). Same behaviour means the same
results **bit for bit**, the same return values, the same exceptions and messages
(checked side by side in ``tests/core/test_pycore.py`` and by the tf2 conformance corpus
run against this core): every formula is the compiled core's, term for term and in the
same order; scalar paths read plain floats (``ndarray.item`` / ``tolist``), never numpy
scalars.

Semantics are tf2's (geometry2 0.7.6); each function names the tf2 source it follows.
A transform is a 7-tuple ``(tx, ty, tz, qx, qy, qz, qw)``: metres, quaternion (x, y, z,
w), never normalised unless said so. Times are int nanoseconds.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from heapq import heappop, heappush
from typing import Any, Final, Literal, TypeVar

import numpy as np

from tfbus.core._pycache import (
    _G_FUTURE,
    _G_OK,
    OK,
    Link,
    StaticCache,
    TimeCache,
)
from tfbus.core._pymath import (
    _IDENTITY,
    _INT64_MAX,
    Tf7,
    _cint,
    _compose,
    _int64,
    _qmul,
    _qrot,
    _tp_name,
)
from tfbus.core.policy import PolicyReport, PolicyResult
from tfbus.core.results import BatchResult, TouchedFrames
from tfbus.errors import InvalidArgumentException
from tfbus.messages import Header, Quaternion, TFMessage, Transform, TransformStamped, Vector3
from tfbus.time import Time

__all__ = [
    "CONNECTIVITY_ERROR",
    "EXTRAPOLATION_ERROR",
    "INVALID",
    "INVALID_ARGUMENT",
    "LOOKUP_ERROR",
    "MAX_GRAPH_DEPTH",
    "NO_ERROR",
    "UNKNOWN_FRAME",
    "CoreBase",
]

# outcomes of the walk and common time (tf2_msgs::TF2Error)
NO_ERROR: Final = 0
LOOKUP_ERROR: Final = 1
CONNECTIVITY_ERROR: Final = 2
EXTRAPOLATION_ERROR: Final = 3

MAX_GRAPH_DEPTH: Final = 1000
"""Walks longer than this are taken to be loops (tf2 ``MAX_GRAPH_DEPTH``)."""

INVALID: Final = 3
"""``CoreBase._store``: the transform breaks one of tf2's rules (setTransformImpl)."""

# Query failures beyond tf2's codes: a bad argument (empty or '/'-prefixed id).
INVALID_ARGUMENT: Final = 4
UNKNOWN_FRAME: Final = 5

# gather outcomes

_CLIMB_STOPPED: Final = 0  # reached the stop frame, or a frame without a link
_CLIMB_EARLY: Final = 1  # reached the other frame of the lookup
_CLIMB_FAILED: Final = 2  # a link had no data at the time
_CLIMB_LOOP: Final = 3  # longer than MAX_GRAPH_DEPTH

_MEMO_SIZE: Final = 64

_new: Final = tuple.__new__  # a NamedTuple without its Python-level __new__

# ---------------------------------------------------------------------- the core


def _link(caches: list[Link | None], frame: int) -> Link | None:
    """The link of ``frame``, or None; an id outside the table (only reachable by writing
    bogus parent ids into a cache by hand) counts as a frame without a link."""
    if frame < 0 or frame >= len(caches):
        return None
    return caches[frame]


def _climb(
    caches: list[Link | None], frame: int, stop: int, early: int, time: int
) -> tuple[int, int, Tf7]:
    """One half of tf2's ``walkToTopParent``: walk up from ``frame`` gathering each link
    at ``time`` and accumulating ``frame -> current``.

    Returns ``(outcome, reached, acc)``: stops at ``stop`` (not gathered), at a frame
    without a link, at a link with no data (CLIMB_FAILED, reached = the failing frame),
    or at ``early`` once its link gathered (CLIMB_EARLY; that link is not accumulated).
    """
    acc = _IDENTITY
    depth = 0
    first = True
    while frame != stop:
        obj = _link(caches, frame)
        if obj is None:
            break
        code, parent, st = obj._c_gather(time)
        if code != _G_OK or parent == 0:
            return _CLIMB_FAILED, frame, acc
        if frame == early:
            return _CLIMB_EARLY, frame, acc
        if first:
            acc = st
            first = False
        else:
            acc = _compose(st, acc)  # TransformAccum::accum: acc = link ∘ acc
        frame = parent
        depth += 1
        if depth > MAX_GRAPH_DEPTH:
            return _CLIMB_LOOP, frame, acc
    return _CLIMB_STOPPED, frame, acc


def _climb_policy(
    caches: list[Link | None],
    frame: int,
    stop: int,
    early: int,
    time: int,
    mode: int,
    before: int,
    after: int,
    frames: list[int],
    stamps: list[int],
) -> tuple[int, int, Tf7]:
    """``_climb`` with each link's sample picked by a lookup policy (``Link._c_pick``);
    appends the child frame and sample stamp of every accumulated link to ``frames`` and
    ``stamps``."""
    acc = _IDENTITY
    depth = 0
    first = True
    while frame != stop:
        obj = _link(caches, frame)
        if obj is None:
            break
        code, parent, st, used = obj._c_pick(time, mode, before, after)
        if code != _G_OK or parent == 0:
            return _CLIMB_FAILED, frame, acc
        if frame == early:
            return _CLIMB_EARLY, frame, acc
        frames.append(frame)
        stamps.append(used)
        if first:
            acc = st
            first = False
        else:
            acc = _compose(st, acc)
        frame = parent
        depth += 1
        if depth > MAX_GRAPH_DEPTH:
            return _CLIMB_LOOP, frame, acc
    return _CLIMB_STOPPED, frame, acc


def _stamped(stamp: Time, target: str, source: str, v: Sequence[float]) -> TransformStamped:
    """The lookup result: ``TransformStamped(Header(stamp, target), source,
    Transform(Vector3(v[0:3]), Quaternion(v[3:7])))``."""
    return _new(
        TransformStamped,
        (
            _new(Header, (stamp, target)),
            source,
            _new(
                Transform,
                (_new(Vector3, (v[0], v[1], v[2])), _new(Quaternion, (v[3], v[4], v[5], v[6]))),
            ),
        ),
    )


def _time_of(ns: int) -> Time:
    """``Time.from_ns(ns)`` for a valid ns, without re-validating it."""
    t = Time.__new__(Time)
    t._ns = ns
    return t


def _as_str(value: object) -> str | None:
    """A frame id as the exact ``str`` it is (``numpy.str_`` or any ``str`` subclass is
    accepted as its string value); None for anything that is not a string."""
    if type(value) is str:
        return value
    if isinstance(value, str):
        return str.__str__(value)
    return None


def _show(value: object) -> str:
    """``repr`` of a bad value for an error message, bounded in length."""
    try:
        text = repr(value)
    except Exception:
        text = f"<{type(value).__name__}>"
    return text if len(text) <= 80 else text[:77] + "..."


def _number(value: object, field: str) -> float:
    """A transform component as a float; anything but a real number (bool, None, str, an
    int beyond double range, ...) is an InvalidArgumentException naming the field."""
    if type(value) is float:
        return value
    if not isinstance(value, (bool, np.bool_, str, bytes, complex)) and value is not None:
        try:
            return float(value)  # type: ignore[arg-type]
        except (OverflowError, TypeError, ValueError):
            pass
    raise InvalidArgumentException(f"{field} must be a real number, got {_show(value)}")


_FIELDS: Final = (
    "transform.translation.x",
    "transform.translation.y",
    "transform.translation.z",
    "transform.rotation.x",
    "transform.rotation.y",
    "transform.rotation.z",
    "transform.rotation.w",
)


def _bad_id(frame_id: str, which: int) -> tuple[int, int]:
    """The failure tuple of a query argument that is not a known frame (tf2
    ``validateFrameId``): empty or '/'-prefixed ids are invalid, others unknown."""
    if not frame_id or frame_id[0] == "/":
        return (INVALID_ARGUMENT, which)
    return (UNKNOWN_FRAME, which)


_Core = TypeVar("_Core", bound="CoreBase")


_NO_FRAMES: Final[frozenset[str]] = frozenset()
"""The frames of a settled wait (``CoreBase._settle``)."""


class CoreBase:
    """Frame table and hot paths of :class:`tfbus.core.BufferCore` (which subclasses it).

    Inserts and queries return codes and data, and ``tfbus.core`` turns them into tf2's
    messages, exceptions and log lines; the calls into the subclass are
    ``set_transform``'s (and ``set_transform_static``'s) for a transform not stored:
    ``_not_stored(problem, authority)``, which logs the refusal or raises, and, with
    waits to settle (``_follow_waits``), for the waits the insert did not settle:
    ``_recheck_rest(rest, relinked)``; ``set_transforms``' for a batch with a refusal or
    an invalid item: ``_batch_result(r, authority)`` (log lines, tf2's exceptions).

    Internals (for white-box tests, never written from outside): ``_frame_ids`` (frame
    id → int id; 0 is tf2's ``NO_PARENT``), ``_frame_names`` (int id → frame id),
    ``_caches`` (int id → link or None), ``_authority`` (int id → authority of its last
    stored transform) and ``_generation`` (bumped by every insert attempt and by
    ``clear``). Python code uses the public methods: ``clear``, ``get_frame_names``,
    ``frame_exists``, ``parent_of``, ``link_info``, ``extrapolation_detail``,
    ``common_time``.

    The state is set up in ``__new__`` (the compiled core's ``__cinit__``), so a
    subclass's ``__init__`` need not call this one.
    """

    __slots__ = (
        "_authority",
        "_cache_ns",
        "_caches",
        "_expire_due",
        "_expire_every",
        "_expire_ns",
        "_expiring",
        "_frame_ids",
        "_frame_names",
        "_frames_expired",
        "_free",
        "_generation",
        "_heap",
        "_last_child",
        "_last_parent",
        "_last_relinked",
        "_last_stamp",
        "_last_values",
        "_lparents",
        "_memo",
        "_memo_generation",
        "_newest",
        "_refs",
        "_replace_repeated",
        "_settled",
        "_waits",
    )

    _frame_ids: dict[str, int]
    _frame_names: list[str]
    _caches: list[Link | None]
    _authority: dict[int, str]
    _generation: int
    _cache_ns: int
    _replace_repeated: bool
    _memo: dict[tuple[str, str, int], TransformStamped]
    _memo_generation: int
    # What the last ``_insert_one`` did, beyond its code (read by ``_store`` and
    # ``_store_one`` right after it): the stripped ids, the stamp, the values (for
    # INVALID only) and whether the tree's shape may have changed.
    _last_parent: str
    _last_child: str
    _last_stamp: int
    _last_values: Tf7
    _last_relinked: bool
    # Frame expiry (``forget``): the free ids of forgotten frames (reused by
    # ``_register``), per id the number of links naming it as a parent (``_refs``) and the
    # parents its own link has named (``_lparents``), a heap of ``(stamp, id)`` per
    # dynamic link (the stamp at most its newest), the newest dynamic stamp stored, and
    # ``expire_after``'s settings and count.
    _free: list[int]
    _refs: list[int]
    _lparents: list[tuple[int, ...] | None]
    _heap: list[tuple[int, int]]
    _newest: int
    _expiring: bool
    _expire_ns: int
    _expire_every: int
    _expire_due: int
    _frames_expired: int
    # The waits inserts settle (``_follow_waits``: the subclass's dict), or None.
    _waits: dict[str, set[Any]] | None
    # Where a settled wait goes, left in ``_waits`` (``_follow_waits``), or None.
    _settled: list[Any] | None
    # BufferCore's: a transform set_transform did not store (the log line or exception).
    _not_stored: Callable[[tuple[Any, ...], str], object]
    # The subclass's recheck of the waits ``_settle`` left (with ``_waits`` only).
    _recheck_rest: Callable[[list[tuple[Any, tuple[int, ...] | None]], bool], None]
    # BufferCore's: the BatchResult of a batch ``_store`` refused or rejected some of.
    _batch_result: Callable[[Any, str], BatchResult]

    def __new__(cls: type[_Core], *args: Any, **kwargs: Any) -> _Core:
        self = super().__new__(cls)
        self._frame_ids = {"NO_PARENT": 0}
        self._frame_names = ["NO_PARENT"]
        self._caches = [None]
        self._authority = {}
        self._generation = 0
        self._cache_ns = 0
        self._replace_repeated = False
        self._memo = {}
        self._memo_generation = -1
        self._last_parent = self._last_child = ""
        self._last_stamp = 0
        self._last_values = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
        self._last_relinked = False
        self._free = []
        self._refs = [0]
        self._lparents = [None]
        self._heap = []
        self._newest = 0
        self._expiring = False
        self._expire_ns = 0
        self._expire_every = 0
        self._expire_due = _INT64_MAX
        self._frames_expired = 0
        self._waits = None
        self._settled = None
        return self

    @property
    def cache_time_ns(self) -> int:
        """The history kept per dynamic link, nanoseconds (the one copy: every link is
        created with it; read-only)."""
        return self._cache_ns

    def _set_cache_time_ns(self, ns: int) -> None:
        """Set the cache time (ns); only before the first insert (``BufferCore.__init__``).

        Raises:
            RuntimeError: frames are already registered.
        """
        if len(self._frame_names) > 1:
            raise RuntimeError("cache_time is fixed once transforms are stored")
        self._cache_ns = _int64(min(ns, _INT64_MAX))

    @property
    def replace_repeated(self) -> bool:
        """Whether a transform whose stamp equals the newest sample of its link replaces
        that sample (``on_repeat="replace"``) instead of being refused as
        TF_REPEATED_DATA (tf2's rule; read-only)."""
        return self._replace_repeated

    def _set_replace_repeated(self, replace: bool) -> None:
        """Set :attr:`replace_repeated`; only before the first insert
        (``BufferCore.__init__``).

        Raises:
            RuntimeError: frames are already registered.
        """
        if len(self._frame_names) > 1:
            raise RuntimeError("on_repeat is fixed once transforms are stored")
        self._replace_repeated = bool(replace)

    def _register(self, frame_id: str) -> int:
        free = self._free
        if free:  # the id of a forgotten frame (its link and counts already reset)
            fid = free.pop()
            self._frame_ids[frame_id] = fid
            self._frame_names[fid] = frame_id
            return fid
        fid = len(self._frame_names)
        self._frame_ids[frame_id] = fid
        self._frame_names.append(frame_id)
        self._caches.append(None)
        self._refs.append(0)
        self._lparents.append(None)
        return fid

    def _name_parent(self, cid: int, pid: int) -> None:
        """Record that the link of ``cid`` named ``pid`` as its parent (once per pair):
        ``pid`` stays known while that link does."""
        ps = self._lparents[cid]
        if ps is None:
            self._lparents[cid] = (pid,)
        elif pid in ps:
            return
        else:
            self._lparents[cid] = (*ps, pid)
        self._refs[pid] += 1

    def _unregister(self, fid: int) -> None:
        """Forget frame ``fid`` (no link, no link naming it): its id becomes unknown and
        its number free for the next new frame."""
        del self._frame_ids[self._frame_names[fid]]
        self._frame_names[fid] = ""
        self._authority.pop(fid, None)
        self._free.append(fid)

    # ------------------------------------------------------------------ expiry

    def _forget(self, older_than: int) -> int:
        """Remove every dynamic link whose newest sample is older than ``older_than``
        (ns, strictly: ``newest < older_than``), as tf2 has no call for (ros/geometry2
        #409, #239). ``BufferCore.forget`` documents the rule; returns the number of
        links removed."""
        older_than = _int64(older_than)
        heap = self._heap
        caches = self._caches
        removed = 0
        while heap and heap[0][0] < older_than:
            _, fid = heappop(heap)
            cache = caches[fid]
            if fid == 0 or not isinstance(cache, TimeCache):
                continue
            newest = cache._c_latest()[0]
            if newest >= older_than:
                heappush(heap, (newest, fid))
                continue
            caches[fid] = None
            self._authority.pop(fid, None)
            ps = self._lparents[fid]
            self._lparents[fid] = None
            refs = self._refs
            if ps is not None:
                for p in ps:
                    refs[p] -= 1
                    if refs[p] == 0 and caches[p] is None and p != 0:
                        self._unregister(p)
            if refs[fid] == 0:
                self._unregister(fid)
            removed += 1
        if removed:
            self._generation += 1
        return removed

    @property
    def frames_expired(self) -> int:
        """How many links ``expire_after`` has removed (``BufferCore.forget`` called
        directly is not counted)."""
        return self._frames_expired

    @property
    def expire_after_ns(self) -> int:
        """``expire_after``'s age limit in ns; 0 when frames never expire."""
        return self._expire_ns if self._expiring else 0

    def _set_expiry(self, after_ns: int, every_ns: int) -> None:
        """Remove, as data arrives, the links whose newest sample is more than
        ``after_ns`` older than the newest dynamic stamp stored, checked whenever that
        stamp has advanced ``every_ns`` since the last check."""
        self._expire_ns = _int64(after_ns)
        self._expire_every = _int64(every_ns)
        self._expiring = True
        self._expire_due = _int64(min(self._newest + self._expire_every, _INT64_MAX))

    def _expire(self) -> None:
        """``expire_after``'s check (the newest stamp reached ``_expire_due``)."""
        if not self._expiring:
            self._expire_due = _INT64_MAX
            return
        self._frames_expired += CoreBase._forget(self, self._newest - self._expire_ns)
        self._expire_due = _int64(min(self._newest + self._expire_every, _INT64_MAX))

    # ------------------------------------------------------------------ insert

    def _insert_one(self, ts: TransformStamped, authority: str, is_static: bool) -> int:
        """``BufferCore::setTransformImpl``: check, register frames, store.

        Returns OK / OLD_DATA / REPEATED_DATA, or INVALID (a tf2 rule is broken). What it
        did beyond the code is left in ``_last_parent``, ``_last_child`` (stripped ids),
        ``_last_stamp`` (ns; not for INVALID), ``_last_values`` (INVALID only) and
        ``_last_relinked``. A field of the wrong type raises InvalidArgumentException
        naming it; nothing is stored or registered before every check has passed."""
        header = ts[0]
        tf = ts[2]
        if not isinstance(header, Header):
            raise InvalidArgumentException(f"header must be a Header, got {_show(header)}")
        if not isinstance(tf, Transform):
            raise InvalidArgumentException(f"transform must be a Transform, got {_show(tf)}")
        tr = tf[0]
        rot = tf[1]
        if not (isinstance(tr, tuple) and len(tr) == 3):
            raise InvalidArgumentException(
                f"transform.translation must be a Vector3, got {_show(tr)}"
            )
        if not (isinstance(rot, tuple) and len(rot) == 4):
            raise InvalidArgumentException(
                f"transform.rotation must be a Quaternion, got {_show(rot)}"
            )
        parent = _as_str(header[1])
        if parent is None:
            raise InvalidArgumentException(f"header.frame_id must be a str, got {_show(header[1])}")
        child = _as_str(ts[1])
        if child is None:
            raise InvalidArgumentException(f"child_frame_id must be a str, got {_show(ts[1])}")
        stamp_obj = header[0]
        if not isinstance(stamp_obj, Time):
            raise InvalidArgumentException(f"header.stamp must be a Time, got {_show(stamp_obj)}")
        v: Tf7 = (
            _number(tr[0], _FIELDS[0]),
            _number(tr[1], _FIELDS[1]),
            _number(tr[2], _FIELDS[2]),
            _number(rot[0], _FIELDS[3]),
            _number(rot[1], _FIELDS[4]),
            _number(rot[2], _FIELDS[5]),
            _number(rot[3], _FIELDS[6]),
        )
        if len(parent) and parent[0] == "/":
            parent = parent[1:]
        if len(child) and child[0] == "/":
            child = child[1:]
        self._last_parent = parent
        self._last_child = child
        # tf2's order (setTransformImpl: w² + x² + y² + z²): it decides cases at the limit.
        norm2 = v[6] * v[6] + v[3] * v[3] + v[4] * v[4] + v[5] * v[5]
        # `v - v == 0` fails for NaN and ±Inf alike; the norm test fails for NaN too.
        if (
            child == parent
            or not child
            or not parent
            or v[0] - v[0] != 0.0
            or v[1] - v[1] != 0.0
            or v[2] - v[2] != 0.0
            or not abs(norm2 - 1.0) < 0.01
        ):
            self._last_values = v
            return INVALID
        stamp = stamp_obj._ns
        self._last_stamp = stamp
        self._generation += 1
        cid = self._frame_ids.get(child)
        if cid is None:
            cid = self._register(child)
        cache = self._caches[cid]
        if cache is None:
            if is_static:
                cache = StaticCache()
            else:
                cache = TimeCache(self._cache_ns, self._replace_repeated)
                heappush(self._heap, (stamp, cid))
            self._caches[cid] = cache
        pid = self._frame_ids.get(parent)
        if pid is None:
            pid = self._register(parent)
        if not is_static and stamp > self._newest:
            self._newest = stamp
        _, old_parent = cache._c_latest()
        if old_parent != pid:
            self._name_parent(cid, pid)
        code = cache._c_insert(stamp, pid, v)
        # The tree's shape may have changed: a new or emptied link, another parent, or a
        # link that keeps one parent per sample.
        self._last_relinked = False
        if code == OK:
            self._last_relinked = old_parent != pid or (
                isinstance(cache, TimeCache) and cache._pa is not None
            )
            self._authority[cid] = authority
        return code

    def _store(
        self, transforms: Iterable[Any], authority: str, is_static: bool
    ) -> (
        BatchResult
        | tuple[
            int,
            list[tuple[int, Exception | tuple[str, str, Tf7]]],
            TouchedFrames,
            bool,
            list[tuple[int, str, int]],
        ]
    ):
        """Store every :class:`~tfbus.messages.TransformStamped` of ``transforms``, in
        order; one bad item never stops the others. Calls nothing back.

        Returns the :class:`~tfbus.core.results.BatchResult` itself when nothing was
        refused and nothing was invalid (the common case). Else the plain tuple
        ``(stored, errors, touched, relinked, refusals)`` for ``BufferCore`` to turn into
        tf2's messages and log lines:

        * ``stored``: how many were stored;
        * ``refusals``: ``[(code, child, stamp ns)]`` for each refused by its cache
          (``OLD_DATA`` / ``REPEATED_DATA``);
        * ``errors``: ``[(index, problem)]``, ``problem`` either an exception
          (InvalidArgumentException for a field of the wrong type, TypeError for an item
          that is not a TransformStamped) or ``(parent, child, values)`` for a transform
          that breaks a tf2 rule (the caller builds tf2's message);
        * ``touched``: a :class:`~tfbus.core.results.TouchedFrames` of the (stripped)
          child and parent ids of every stored transform;
        * ``relinked``: whether a stored transform may have changed the tree's shape.

        Raises:
            TypeError: ``authority`` is not a str (nor None).
        """
        if authority is not None and type(authority) is not str:
            raise TypeError(
                f"Argument 'authority' has incorrect type (expected str, got {_tp_name(authority)})"
            )
        is_static = bool(is_static)
        stored = 0
        refusals: list[tuple[int, str, int]] = []
        errors: list[tuple[int, Exception | tuple[str, str, Tf7]]] = []
        ids: list[str] = []
        relinked = False
        for i, ts in enumerate(transforms):
            try:
                if not isinstance(ts, TransformStamped):
                    raise TypeError(f"expected TransformStamped, got {type(ts).__name__}")
                code = self._insert_one(ts, authority, is_static)
            except Exception as exc:
                errors.append((i, exc))
            else:
                if code == OK:
                    stored += 1
                    ids.append(self._last_child)
                    ids.append(self._last_parent)
                    if self._last_relinked:
                        relinked = True
                elif code == INVALID:
                    errors.append((i, (self._last_parent, self._last_child, self._last_values)))
                else:
                    refusals.append((code, self._last_child, self._last_stamp))
        touched = TouchedFrames(ids)
        if self._newest >= self._expire_due:
            self._expire()
        if not (errors or refusals):
            return BatchResult(stored, 0, [], touched, relinked)
        return stored, errors, touched, relinked, refusals

    def set_transforms(
        self,
        transforms: Iterable[TransformStamped],
        authority: str = "default",
        is_static: bool = False,
    ) -> BatchResult:
        """Store a batch of transforms (a ``TFMessage``'s worth) in one call: what the
        listener uses. With the compiled twin it is cheaper per transform than a loop of
        :meth:`set_transform` from about five transforms a call on (this twin is only as
        fast as Python); one transform a call pays for the
        :class:`~tfbus.core.results.BatchResult` beside the insert.

        Each item is handled exactly as :meth:`set_transform` (or
        :meth:`set_transform_static` when ``is_static``) would, in order; an invalid or
        malformed item is reported in ``errors`` instead of raising, and never stops the
        items after it. Refusals (TF_OLD_DATA, TF_REPEATED_DATA) are logged, the first
        of each kind then one per 1000.

        Args:
            transforms: an iterable of :class:`~tfbus.messages.TransformStamped`.
            authority: who sent them (shown by ``all_frames_as_yaml``).
            is_static: store them as :meth:`set_transform_static` does.

        Returns:
            A :class:`~tfbus.core.results.BatchResult`: counts, errors, and the frames it
            touched (what a subclass needs to react to the insert).

        Raises:
            TypeError: ``authority`` is not a str.

        The core's method (``BufferCore`` and ``Buffer`` inherit it, as from the compiled
        twin). A batch with a refusal or an invalid item gets its result from the
        subclass's ``_batch_result`` (log lines, tf2's exceptions). With waits to settle
        (``_follow_waits``), the waits on the ids the batch touched are settled here,
        once per batch (``_settle``), and what is left goes to the subclass's
        ``_recheck_rest(rest, relinked)``.
        """
        r = self._store(transforms, authority, is_static)
        result = r if type(r) is BatchResult else self._batch_result(r, authority)
        waits = self._waits
        if waits:
            touched = result.touched
            # The ids recorded by the insert (repeats allowed; no set built for them).
            names = touched._ids if type(touched) is TouchedFrames else touched
            rest = self._settle(waits, names)
            if rest is not None:
                self._recheck_rest(rest, result.relinked)
        return result

    def set_transform(self, transform: TransformStamped, authority: str = "default") -> bool:
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

        The core's method (``BufferCore`` inherits it, as from the compiled twin); a
        transform not stored goes to the subclass's ``_not_stored``. With waits to settle
        (``_follow_waits``), a stored transform settles them here (``_settle``), and what
        is left goes to the subclass's ``_recheck_rest(rest, relinked)``.
        """
        return self._set_one(transform, authority, False)

    def set_transform_static(
        self, transform: TransformStamped, authority: str = "default"
    ) -> bool:
        """Store a static transform: valid at all times, overwritten by every later send
        (tf2 ``setTransform(..., is_static=true)``). Whether a link is static is fixed by
        its first accepted transform, as in tf2.

        Returns and raises as :meth:`set_transform`.
        """
        return self._set_one(transform, authority, True)

    def _set_one(self, transform: TransformStamped, authority: str, is_static: bool) -> bool:
        """``set_transform`` (``is_static`` False) and ``set_transform_static`` (True): the
        insert, expiry when due, then the waits the insert answers settled in the core
        (when ``_waits`` holds any; the rest to the subclass's ``_recheck_rest``), or a
        transform not stored to the subclass's ``_not_stored``."""
        r = self._store_one(transform, authority, is_static)
        if r is True:
            waits = self._waits
            if waits:
                rest = self._settle(waits, None)
                if rest is not None:
                    self._recheck_rest(rest, self._last_relinked)
            return True
        self._not_stored(r, authority)
        return False

    def _store_one(
        self, ts: Any, authority: str, is_static: bool
    ) -> Literal[True] | tuple[int, str, int] | tuple[int, str, str, Tf7]:
        """One transform, as ``_store`` would store it (``BufferCore.set_transform``'s
        path). Calls nothing back.

        Returns True when stored; else what ``_store`` reports for it: ``(OLD_DATA |
        REPEATED_DATA, child, stamp ns)`` for a refusal by the cache, ``(INVALID, parent,
        child, values)`` for a transform that breaks a tf2 rule.

        Raises:
            TypeError: ``ts`` is not a TransformStamped, or ``authority`` not a str.
            InvalidArgumentException: a field of the wrong type (named).
        """
        if authority is not None and type(authority) is not str:
            raise TypeError(
                f"Argument 'authority' has incorrect type (expected str, got {_tp_name(authority)})"
            )
        if not isinstance(ts, TransformStamped):
            raise TypeError(f"expected TransformStamped, got {type(ts).__name__}")
        code = self._insert_one(ts, authority, bool(is_static))
        if self._newest >= self._expire_due:
            self._expire()
        if code == OK:
            return True
        if code == INVALID:
            return (INVALID, self._last_parent, self._last_child, self._last_values)
        return (code, self._last_child, self._last_stamp)

    def _last_touched(self) -> tuple[str, str, bool]:
        """``(child, parent, relinked)`` of the transform ``_store_one`` last stored: the
        (stripped) ids whose lookups may have changed and whether the tree's shape may
        have (what ``_store`` reports per batch); read by ``tfbus.buffer.Buffer`` when
        waits are pending."""
        return self._last_child, self._last_parent, self._last_relinked

    @staticmethod
    def _plain_transform(ts: object) -> bool:
        """Whether ``ts`` is a transform every ``set_transform`` accepts, by a quick test
        of its common form: a ``TransformStamped`` of the message classes themselves (no
        subclass), stamp a ``Time``, two different ``str`` ids, neither empty nor
        '/'-prefixed, seven ``float`` values, a finite translation and a quaternion
        whose squared norm (w² + x² + y² + z², tf2's order) is within 0.01 of 1.

        False says only that the quick test does not decide (the broadcaster then asks
        ``set_transform`` itself, the one authority on validity); never raises."""
        if type(ts) is not TransformStamped or len(ts) != 3:
            return False
        header, child, tf = ts
        if type(header) is not Header or len(header) != 2:
            return False
        if type(tf) is not Transform or len(tf) != 2:
            return False
        tr, rot = tf
        if type(tr) is not Vector3 or len(tr) != 3:
            return False
        if type(rot) is not Quaternion or len(rot) != 4:
            return False
        stamp, parent = header
        if type(stamp) is not Time or type(parent) is not str or type(child) is not str:
            return False
        if not parent or not child or parent[0] == "/" or child[0] == "/" or parent == child:
            return False
        if not all(type(value) is float for value in (*tr, *rot)):
            return False
        x, y, z = tr
        qx, qy, qz, qw = rot
        s = x + y + z
        if s - s != 0.0:  # NaN or ±Inf anywhere makes the sum non-finite
            return False
        return abs(qw * qw + qx * qx + qy * qy + qz * qz - 1.0) < 0.01  # False for NaN

    @staticmethod
    def _message_of_one(ts: object) -> TFMessage | None:
        """The ``TFMessage`` of ``ts`` alone (``TFMessage((ts,))``) when
        :meth:`_plain_transform` accepts it, else None (the broadcaster then checks ``ts``
        and makes the message itself). What a broadcaster's send of one transform needs,
        in one call; never raises."""
        if not CoreBase._plain_transform(ts):
            return None
        # TFMessage((ts,)) without the Python frame of the NamedTuple's __new__
        message: TFMessage = tuple.__new__(TFMessage, ((ts,),))
        return message

    def _follow_waits(
        self, index: dict[str, set[Any]] | None, settled: list[Any] | None = None
    ) -> None:
        """Settle the waits of ``index`` (frame id -> set of waits, the subclass's own
        dict, kept by reference) in every later ``set_transform`` and
        ``set_transform_static`` that stores (see :meth:`_settle`); ``None`` stops.
        ``settled``: the subclass's list (kept by reference) that a settled wait is
        appended to, left in ``index`` for the subclass to remove later (off the
        wake-up's path); None: removed from ``index`` as it is settled."""
        self._waits = index
        self._settled = settled

    def _settle(
        self, index: dict[str, set[Any]], names: Iterable[str] | None
    ) -> list[tuple[Any, tuple[int, ...] | None]] | None:
        """The recheck of ``tfbus.buffer.Buffer``'s waits after an insert, in one call:
        every wait indexed in ``index`` (frame id -> set of waits) under one of
        ``names`` (the ids the insert touched, repeats allowed; ``None``: the two ids of
        the transform ``_store_one`` stored last) is taken once. An exact wait (its
        ``exact`` is ``(target, source, time, fail_fast)``) whose lookup now succeeds is
        settled here: ``result`` := the transform, removed from ``index`` under each of
        its ``frames`` (then empty) or, with a ``settled`` list (:meth:`_follow_waits`),
        appended to it and left in ``index`` (``frames`` kept; a wait with a ``result``
        is skipped by every later settle), and woken (``future.set_result(None)`` unless
        done on asyncio, else its ``wake()``).

        Returns:
            None when nothing is left to do; else ``[(wait, failure)]`` for the buffer's
            own recheck: an exact wait whose lookup failed (``failure``, ``_query``'s
            tuple) or another wait (``failure`` None).
        """
        if names is None:
            names = (self._last_child, self._last_parent)
        first: set[Any] | None = None
        union: set[Any] | None = None
        for name in names:
            ws = index.get(name)
            if ws is None or ws is first:
                continue
            if first is None:
                first = ws
            elif union is None:
                union = set(first)
                union.update(ws)
            else:
                union.update(ws)
        if first is None:
            return None
        # A copy: settling a wait edits the index's sets (unless ``settled`` is kept).
        due = list(first) if union is None else list(union)
        rest: list[tuple[Any, tuple[int, ...] | None]] | None = None
        settled = self._settled
        for waiter in due:
            if waiter.result is not None:
                continue  # settled before, still in the index (``settled``)
            exact = waiter.exact
            out: tuple[int, ...] | None = None
            if exact is not None:
                found = self._query(exact[0], exact[1], exact[2])
                if isinstance(found, TransformStamped):
                    waiter.result = found
                    if settled is not None:
                        settled.append(waiter)
                    else:
                        for name in waiter.frames:
                            ws = index.get(name)
                            if ws is not None:
                                ws.discard(waiter)
                                if not ws:
                                    del index[name]
                        waiter.frames = _NO_FRAMES
                    future = waiter.future
                    if future is None:
                        waiter.wake()
                    elif not future.done():
                        future.set_result(None)
                    continue
                out = found
            if rest is None:
                rest = []
            rest.append((waiter, out))
        return rest

    # ------------------------------------------------------------------ queries

    def _id_status(self, frame_id: object) -> int:
        """0 for a known, queryable frame id; else INVALID_ARGUMENT (not a string, empty,
        '/'-prefixed) or UNKNOWN_FRAME (tf2 ``validateFrameId``)."""
        name = _as_str(frame_id)
        if name is None:
            return INVALID_ARGUMENT
        if self._frame(name) >= 0:
            return 0
        return _bad_id(name, 0)[0]

    def _frame(self, frame_id: Any) -> int:
        """Id of a known, queryable frame, or -1 (empty, '/'-prefixed, unknown)."""
        fid = self._frame_ids.get(frame_id)
        if fid is None or fid == 0:
            return -1
        if type(frame_id) is not str or not len(frame_id) or frame_id[0] == "/":
            return -1
        return fid

    def lookup_transform(
        self, target_frame: str, source_frame: str, time: Time, policy: object = None
    ) -> Any:
        """``BufferCore.lookup_transform`` (documented there): the compiled core's entry,
        the same steps: a policy lookup, a failure or a ``time`` that is not a Time goes
        on to ``BufferCore``'s ``_lookup_by_policy`` / ``_lookup_failed``."""
        if policy is not None:
            return self._lookup_by_policy(  # type: ignore[attr-defined]
                target_frame, source_frame, time, policy)
        try:
            out = self._query(target_frame, source_frame, time)
        except AttributeError as err:  # time._ns: not a Time
            return self._lookup_failed(  # type: ignore[attr-defined]
                target_frame, source_frame, time, err)
        if type(out) is TransformStamped:
            return out
        return self._lookup_failed(  # type: ignore[attr-defined]
            target_frame, source_frame, time, out)

    def _query(self, target: str, source: str, time: Time) -> TransformStamped | tuple[int, ...]:
        """``lookupTransform(target, source, time)`` in one call: the TransformStamped
        (built here, memoised until the next insert or clear), or a failure tuple:

        * ``(INVALID_ARGUMENT, 0 | 1)`` / ``(UNKNOWN_FRAME, 0 | 1)``: the target (0) or
          source (1) id is empty / '/'-prefixed, or unknown;
        * ``(LOOKUP_ERROR, 0)``: a loop; ``(CONNECTIVITY_ERROR, 0)``: two trees;
        * ``(EXTRAPOLATION_ERROR, frame id, time ns, expired)``: the link of that frame has
          no data at the time; ``expired`` when the time is older than the path's latest
          common time minus cache_time (tf2's transformable-request test), i.e. waiting
          cannot help.

        Source: tf2 ``BufferCore::lookupTransform`` / ``walkToTopParent``.
        """
        t = _int64(time._ns)
        if type(target) is not str:
            name = _as_str(target)
            if name is None:
                return (INVALID_ARGUMENT, 0)
            target = name
        if type(source) is not str:
            name = _as_str(source)
            if name is None:
                return (INVALID_ARGUMENT, 1)
            source = name
        key = (target, source, t)
        if self._memo_generation == self._generation:
            hit = self._memo.get(key)
            if hit is not None:
                return hit
        else:
            self._memo.clear()
            self._memo_generation = self._generation
        if target == source:
            if t == 0:
                # tf2 stamps the identity with the frame's newest sample; an unknown id
                # maps to frame 0 (NO_PARENT), whose link exists only if "NO_PARENT" was
                # stored as a child (lookupFrameNumber / getFrame).
                cache = self._caches[self._frame_ids.get(target, 0)]
                if cache is not None:
                    t = cache._c_latest()[0]
            return _stamped(_time_of(t) if t != time._ns else time, target, source, _IDENTITY)
        target_id = self._frame(target)
        if target_id < 0:
            return _bad_id(target, 0)
        source_id = self._frame(source)
        if source_id < 0:
            return _bad_id(source, 1)
        err, v, where, used = self._walk(target_id, source_id, t)
        if err != NO_ERROR:
            if err != EXTRAPOLATION_ERROR:
                return (err, 0)
            expired = False
            link = self._caches[where]
            assert link is not None
            gcode = link._c_gather(used)[0]
            if gcode != _G_FUTURE:
                cerr, lct = self._common(target_id, source_id)
                if cerr == NO_ERROR:
                    expired = lct != 0 and used < lct - self._cache_ns
            return (err, where, used, expired)
        out = _stamped(time if used == t and t != 0 else _time_of(used), target, source, v)
        if len(self._memo) >= _MEMO_SIZE:
            self._memo.clear()
        self._memo[key] = out
        return out

    def _chain(self, target_frame: str, source_frame: str, time: Time | None = None) -> list[str]:
        """The frames an answer for ``lookup_transform(target_frame, source_frame, time)``
        depends on, now and as data arrives: both ids, and the ancestors of each by its
        link's newest parent and, for a time other than 0, by its parent at ``time`` (a
        link re-parented over time), at most ``MAX_GRAPH_DEPTH + 1`` per chain (a longer
        walk is tf2's loop error). Unknown ids are included as given (they may arrive).
        Like tf2's ``_chainAsVector``, but as a set and for both parentage rules.

        Returns:
            A list of frame ids (no duplicates, in discovery order).
        """
        t = 0 if time is None else _int64(time._ns)
        names = self._frame_names
        caches = self._caches
        seen: set[str] = set()
        out: list[str] = []
        todo: list[str] = [target_frame, source_frame]
        while todo:
            name = todo.pop()
            if name in seen:
                continue
            seen.add(name)
            out.append(name)
            fid = self._frame_ids.get(name)
            if fid is None:
                continue
            frame = fid
            depth = 0
            while frame != 0 and depth <= MAX_GRAPH_DEPTH:
                obj = _link(caches, frame)
                if obj is None:
                    break
                if t != 0:
                    code, p2, _ = obj._c_gather(t)
                    if code == _G_OK and p2 != 0 and names[p2] not in seen:
                        todo.append(names[p2])
                _, parent = obj._c_latest()
                if parent == 0 or parent >= len(names):
                    break
                name = names[parent]
                if name in seen:
                    break
                seen.add(name)
                out.append(name)
                frame = parent
                depth += 1
        return out

    # ------------------------------------------------------------------ the walk

    def _common(self, target: int, source: int) -> tuple[int, int]:
        """tf2 ``getLatestCommonTime``: ``(NO_ERROR, time ns)`` or ``(error code, 0)``."""
        caches = self._caches
        if source == target:
            obj = _link(caches, source)
            return NO_ERROR, obj._c_latest()[0] if obj is not None else 0
        # Walk up from the source, remembering (stamp, parent) of each link.
        lct_stamp: list[int] = []
        lct_parent: list[int] = []
        frame = source
        common = _INT64_MAX
        have = False
        depth = 0
        while frame != 0:
            obj = _link(caches, frame)
            if obj is None:
                break
            stamp, parent = obj._c_latest()
            if parent == 0:
                break
            if stamp and (not have or stamp < common):
                common = stamp
                have = True
            lct_stamp.append(stamp)
            lct_parent.append(parent)
            frame = parent
            if frame == target:
                return NO_ERROR, common if have else 0
            depth += 1
            if depth > MAX_GRAPH_DEPTH:
                return LOOKUP_ERROR, 0
        # Walk up from the target until a parent seen on the source side.
        frame = target
        depth = 0
        have = False
        common = _INT64_MAX
        common_parent = 0
        while True:
            obj = _link(caches, frame)
            if obj is None:
                break
            stamp, parent = obj._c_latest()
            if parent == 0:
                break
            if stamp and (not have or stamp < common):
                common = stamp
                have = True
            if parent in lct_parent:
                common_parent = parent
                break
            frame = parent
            if frame == source:
                return NO_ERROR, common if have else 0
            depth += 1
            if depth > MAX_GRAPH_DEPTH:
                return LOOKUP_ERROR, 0
        if common_parent == 0:
            return CONNECTIVITY_ERROR, 0
        for k in range(len(lct_parent)):
            stamp = lct_stamp[k]
            if stamp and (not have or stamp < common):
                common = stamp
                have = True
            if lct_parent[k] == common_parent:
                break
        return NO_ERROR, common if have else 0

    def _ccommon_time(self, target_id: int, source_id: int) -> tuple[int, int]:
        """``(NO_ERROR, time ns)``, or ``(LOOKUP_ERROR (loop) | CONNECTIVITY_ERROR, 0)``
        (tf2 ``getLatestCommonTime``)."""
        err, t = self._common(_cint(target_id), _cint(source_id))
        return err, (t if err == NO_ERROR else 0)

    # ------------------------------------------------------------------ public state

    def clear(self) -> None:
        """Drop every stored sample, keeping the frames and their links (tf2
        ``BufferCore::clear``). As in tf2, the reserved frame 0 (``NO_PARENT``) is
        skipped: a link stored with child ``"NO_PARENT"`` keeps its samples."""
        self._generation += 1
        caches: list[Any] = self._caches  # TimeCache / StaticCache (Link's subclasses)
        for cache in caches[1:]:
            if cache is not None:
                cache.clear()
        # Every dynamic link's newest stamp is 0 now: ``forget`` finds them first; the
        # newest stamp stored starts over (a clock that jumped back: older stamps follow).
        self._newest = 0
        if self._expiring:
            self._expire_due = self._expire_every
        self._heap = [
            (0, fid) for fid in range(1, len(caches)) if isinstance(caches[fid], TimeCache)
        ]

    def get_frame_names(self) -> list[str]:
        """Every known frame id (children and parents), in the order of their numbers
        (registration order; a frame registered after ``forget`` may take the number of
        a forgotten one)."""
        if self._free:
            return [name for name in self._frame_names[1:] if name]
        return self._frame_names[1:]

    def frame_exists(self, frame_id: str) -> bool:
        """Whether ``frame_id`` is known (tf2 ``_frameExists``)."""
        return self._frame_ids.get(frame_id, 0) != 0

    def parent_of(self, frame_id: str, time_ns: int) -> str | None:
        """The parent id of ``frame_id`` at ``time_ns`` (0 = latest), or None for a root,
        an unknown frame or a time its link has no data for (tf2 ``_getParent``)."""
        time_ns = _int64(time_ns)
        fid = self._frame_ids.get(frame_id, 0)
        cache = self._caches[fid] if fid else None
        if cache is None:
            return None
        r = cache.gather(time_ns)
        if isinstance(r, str) or r[0] == 0:
            return None
        return self._frame_names[r[0]]

    def link_info(self) -> list[tuple[str, str, str, bool, int, int, int]]:
        """Per linked frame, in registration order, ``(child, parent, authority,
        is_static, samples, oldest_ns, newest_ns)``; the parent of an emptied link is
        ``NO_PARENT``, a link with no recorded authority says so."""
        names = self._frame_names
        caches: list[Any] = self._caches  # TimeCache / StaticCache (Link's subclasses)
        out = []
        for fid in range(1, len(caches)):
            cache = caches[fid]
            if cache is None:
                continue
            r = cache.gather(0)
            out.append((
                names[fid],
                names[0 if isinstance(r, str) else r[0]],
                self._authority.get(fid, "no recorded authority"),
                cache.is_static,
                len(cache),
                cache.oldest_stamp(),
                cache.latest_stamp(),
            ))  # fmt: skip
        return out

    def extrapolation_detail(self, where: int, used: int) -> str:
        """tf2's extrapolation text of the link of frame ``where`` (the int id a failed
        query reported) at ``used`` ns: ``"Lookup would require extrapolation ..."``;
        ``""`` for no link or a link that can answer that time."""
        where, used = _cint(where), _int64(used)
        cache = self._caches[where] if 0 < where < len(self._caches) else None
        detail = cache.gather(used) if cache is not None else ""
        return detail if isinstance(detail, str) else ""

    def common_time(self, target_frame: str, source_frame: str) -> tuple[int, int]:
        """tf2 ``getLatestCommonTime`` for two known frame ids: ``(NO_ERROR, time ns)``,
        or ``(LOOKUP_ERROR (a loop) | CONNECTIVITY_ERROR, 0)``.

        Raises:
            KeyError: an id is unknown (validate first).
        """
        return self._ccommon_time(self._frame_ids[target_frame], self._frame_ids[source_frame])

    def _walk(self, target_id: int, source_id: int, time: int) -> tuple[int, Tf7, int, int]:
        """tf2 ``walkToTopParent`` with ``TransformAccum``: ``(code, v, where, time
        used)``, ``v`` the transform mapping source coordinates into target coordinates at
        the time used (``time`` 0 = the latest common time). ``code`` is NO_ERROR,
        LOOKUP_ERROR (a loop), CONNECTIVITY_ERROR, or EXTRAPOLATION_ERROR with ``where``
        = the frame whose link had no data."""
        caches = self._caches
        if source_id == target_id:
            return NO_ERROR, _IDENTITY, 0, time
        if time == 0:
            err, time = self._common(target_id, source_id)
            if err:
                return err, _IDENTITY, 0, time

        # Source side: source -> top. A failure here is only remembered: the path may
        # still close below it (only links between the two frames must be valid).
        outcome, top, src = _climb(caches, source_id, 0, target_id, time)
        if outcome == _CLIMB_EARLY:  # TargetParentOfSource
            return NO_ERROR, src, 0, time
        if outcome == _CLIMB_LOOP:
            return LOOKUP_ERROR, _IDENTITY, 0, time
        failed = outcome == _CLIMB_FAILED
        src_failed_at = top if failed else 0

        # Target side: target -> top. A failure here is reported at once.
        outcome, frame, tgt = _climb(caches, target_id, top, source_id, time)
        if outcome == _CLIMB_FAILED:
            return EXTRAPOLATION_ERROR, _IDENTITY, frame, time
        if outcome == _CLIMB_LOOP:
            return LOOKUP_ERROR, _IDENTITY, 0, time
        if outcome == _CLIMB_EARLY:  # SourceParentOfTarget: the source side is unused
            src = _IDENTITY
        elif frame != top:
            if failed:
                return EXTRAPOLATION_ERROR, _IDENTITY, src_failed_at, time
            return CONNECTIVITY_ERROR, _IDENTITY, 0, time

        # FullPath: inv(target -> top) ∘ (source -> top), inv = (conj q, conj q * (-t)):
        # conj(q) applied to (s - g), then conj(q) ⊗ q_s.
        iqx, iqy, iqz, iqw = -tgt[3], -tgt[4], -tgt[5], tgt[6]
        rx, ry, rz = _qrot(iqx, iqy, iqz, iqw, src[0] - tgt[0], src[1] - tgt[1], src[2] - tgt[2])
        qx, qy, qz, qw = _qmul(iqx, iqy, iqz, iqw, src[3], src[4], src[5], src[6])
        return NO_ERROR, (rx, ry, rz, qx, qy, qz, qw), 0, time

    def _walk_policy(
        self, target_id: int, source_id: int, time: int, mode: int, before: int, after: int
    ) -> tuple[int, Tf7, int, int, list[int], list[int]]:
        """``_walk`` with each link's sample picked by a lookup policy: ``(code, v, where,
        time used, frames, stamps)``, ``frames`` / ``stamps`` the child frame and sample
        stamp of each link on the path (source side upwards, then target side downwards;
        links above the common ancestor, gathered by both sides, are left out)."""
        caches = self._caches
        sf: list[int] = []
        ss: list[int] = []
        tf_: list[int] = []
        ts_: list[int] = []
        if source_id == target_id:
            return NO_ERROR, _IDENTITY, 0, time, sf, ss
        if time == 0:
            err, time = self._common(target_id, source_id)
            if err:
                return err, _IDENTITY, 0, time, sf, ss
        outcome, top, src = _climb_policy(
            caches, source_id, 0, target_id, time, mode, before, after, sf, ss
        )
        if outcome == _CLIMB_EARLY:
            return NO_ERROR, src, 0, time, sf, ss
        if outcome == _CLIMB_LOOP:
            return LOOKUP_ERROR, _IDENTITY, 0, time, sf, ss
        failed = outcome == _CLIMB_FAILED
        src_failed_at = top if failed else 0
        outcome, frame, tgt = _climb_policy(
            caches, target_id, top, source_id, time, mode, before, after, tf_, ts_
        )
        if outcome == _CLIMB_FAILED:
            return EXTRAPOLATION_ERROR, _IDENTITY, frame, time, sf, ss
        if outcome == _CLIMB_LOOP:
            return LOOKUP_ERROR, _IDENTITY, 0, time, sf, ss
        if outcome == _CLIMB_EARLY:
            src = _IDENTITY
            sf = []
            ss = []
        elif frame != top:
            if failed:
                return EXTRAPOLATION_ERROR, _IDENTITY, src_failed_at, time, sf, ss
            return CONNECTIVITY_ERROR, _IDENTITY, 0, time, sf, ss
        # The links above the common ancestor were gathered by both sides: drop them.
        n, m = len(sf), len(tf_)
        while n and m and sf[n - 1] == tf_[m - 1]:
            n -= 1
            m -= 1
        iqx, iqy, iqz, iqw = -tgt[3], -tgt[4], -tgt[5], tgt[6]
        rx, ry, rz = _qrot(iqx, iqy, iqz, iqw, src[0] - tgt[0], src[1] - tgt[1], src[2] - tgt[2])
        qx, qy, qz, qw = _qmul(iqx, iqy, iqz, iqw, src[3], src[4], src[5], src[6])
        sf = sf[:n] + tf_[:m][::-1]
        ss = ss[:n] + ts_[:m][::-1]
        return NO_ERROR, (rx, ry, rz, qx, qy, qz, qw), 0, time, sf, ss

    def _query_policy(
        self, target: str, source: str, time: Time, policy: tuple[int, int, int]
    ) -> PolicyResult | tuple[int, ...]:
        """``_query`` under a lookup policy (:mod:`tfbus.core.policy`; ``policy`` its
        ``(mode, before ns, after ns)``, mode 1 nearest, 2 clamp, 3 previous): the
        :class:`~tfbus.core.policy.PolicyResult` (transform and report, not memoised), or
        ``_query``'s failure tuple (the failing link's tf2 failure at the time)."""
        t = _int64(time._ns)
        if type(policy) is not tuple:
            raise TypeError(f"policy must be a tuple, not {type(policy).__name__}")
        mode, before, after = _cint(policy[0]), _int64(policy[1]), _int64(policy[2])
        if type(target) is not str:
            name = _as_str(target)
            if name is None:
                return (INVALID_ARGUMENT, 0)
            target = name
        if type(source) is not str:
            name = _as_str(source)
            if name is None:
                return (INVALID_ARGUMENT, 1)
            source = name
        if target == source:
            out = self._query(target, source, time)
            assert isinstance(out, TransformStamped)
            return _new(PolicyResult, (out, _new(PolicyReport, ((), (), 0))))
        target_id = self._frame(target)
        if target_id < 0:
            return _bad_id(target, 0)
        source_id = self._frame(source)
        if source_id < 0:
            return _bad_id(source, 1)
        err, v, where, used, fr, stamps = self._walk_policy(
            target_id, source_id, t, mode, before, after
        )
        if err != NO_ERROR:
            if err != EXTRAPOLATION_ERROR:
                return (err, 0)
            expired = False
            link = self._caches[where]
            assert link is not None
            gcode = link._c_gather(used)[0]
            if gcode != _G_FUTURE:
                cerr, lct = self._common(target_id, source_id)
                if cerr == NO_ERROR:
                    expired = lct != 0 and used < lct - self._cache_ns
            return (err, where, used, expired)
        names = self._frame_names
        worst = 0
        for s in stamps:
            d = s - used if s >= used else used - s
            if d > worst:
                worst = d
        out = _stamped(time if used == t and t != 0 else _time_of(used), target, source, v)
        report = _new(PolicyReport, (tuple([names[f] for f in fr]), tuple(stamps), worst))
        return _new(PolicyResult, (out, report))

    def _cwalk(
        self, target_id: int, source_id: int, time: int
    ) -> tuple[int, Tf7 | int | None, int]:
        """tf2 ``walkToTopParent`` with ``TransformAccum`` (see ``_walk``).

        Returns ``(NO_ERROR, 7-tuple, time used)``, ``(EXTRAPOLATION_ERROR, id of the
        frame whose link had no data, time)``, ``(CONNECTIVITY_ERROR, None, 0)`` or
        ``(LOOKUP_ERROR, None, 0)`` (a loop).
        """
        err, v, where, used = self._walk(_cint(target_id), _cint(source_id), _int64(time))
        if err == NO_ERROR:
            return NO_ERROR, v, used
        if err == EXTRAPOLATION_ERROR:
            return err, where, used
        return err, None, 0

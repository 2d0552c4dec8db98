# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, embedsignature=True
"""Compiled heart of :class:`tfbus.core.BufferCore`: the frame table, insert and the walk
(the twin of :mod:`tfbus.core._pycore`).

Semantics are tf2's (geometry2 0.7.6); every rule here is a transcription of the tf2 C++
named next to it, and the arithmetic is done in the same order as tf2, in IEEE doubles
with no fused multiply-add, so results are bit-for-bit tf2's (checked by the
conformance corpus, ``tests/core/test_conformance.py``).

:class:`CoreBase` is the frame table and the hot paths of ``BufferCore``: ``_store``
(``BufferCore::setTransformImpl`` over a batch: returns counts, refusals, problems and
the frames it touched) and ``_store_one`` (one transform: True, or what it refused and
why), ``_query`` (``lookupTransform`` in one call: checks, memo, ``walkToTopParent`` with
``TransformAccum``, the TransformStamped built here; or a failure tuple), ``_chain`` (the
frames an answer depends on), ``_cwalk`` and ``common_time`` (``getLatestCommonTime``),
and the public ``clear``, ``get_frame_names``, ``frame_exists``, ``parent_of``,
``link_info``, ``extrapolation_detail`` through which ``BufferCore`` reads its state.
Error *messages* and log lines are built by :mod:`tfbus.core.buffer_core` from the codes
returned here; the one call into the Python subclass is ``set_transform``'s (and
``set_transform_static``'s) for a transform not stored: ``_not_stored(problem,
authority)``, which logs the refusal or raises.

The links are :mod:`tfbus.core._ccache`'s, the scalar math ``_cmath.pxd``'s inline
functions; ``_ccore.pxd`` declares the table and the walk for the batch kernel
(:mod:`tfbus.core._cbatch`).
"""

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


import numpy as np
from heapq import heappop, heappush

from libc.stdint cimport INT64_MAX, int64_t
from libc.string cimport memcpy
from cpython.dict cimport PyDict_GetItem
from cpython.list cimport PyList_GET_SIZE
from cpython.tuple cimport PyTuple_GET_SIZE
from cpython.object cimport PyObject
from cpython.unicode cimport PyUnicode_GET_LENGTH, PyUnicode_READ_CHAR

from libc.math cimport fabs, sqrt
from tfbus.core._ccache cimport (
    C_INVALID, C_MAX_DEPTH, C_OK, C_OLD_DATA, C_REPEATED_DATA, CLIMB_EARLY, CLIMB_FAILED,
    CLIMB_LOOP, CLIMB_STOPPED, G_AT, G_EMPTY, G_FUTURE, G_OK, G_PAST, Link, StaticCache,
    TimeCache, _detail, _link,
)
from tfbus.core._cmath cimport _accumulate, _compose, _identity, _qrot, _qmul
from cpython.float cimport PyFloat_FromDouble
from cpython.ref cimport Py_DECREF, Py_INCREF
from cpython.tuple cimport PyTuple_New, PyTuple_SET_ITEM

from tfbus.core._cresults cimport (
    PyObject_GC_UnTrack, PyObject_GenericSetAttr, PyType_GenericAlloc, PyTypeObject, _named,
    _named3, _named4, _named5,
)
from tfbus.errors import InvalidArgumentException
from tfbus.messages import Header, Quaternion, TFMessage, Transform, TransformStamped, Vector3
from tfbus.time import Time
from tfbus.core.policy import PolicyReport, PolicyResult
from tfbus.core.results import BatchResult, TouchedFrames


# outcomes of BufferCore._cwalk / _ccommon_time (tf2_msgs::TF2Error)
NO_ERROR = 0
LOOKUP_ERROR = 1
CONNECTIVITY_ERROR = 2
EXTRAPOLATION_ERROR = 3

MAX_GRAPH_DEPTH = 1000
"""Walks longer than this are taken to be loops (tf2 ``MAX_GRAPH_DEPTH``)."""


# ---------------------------------------------------------------------- results

cdef object _stamped(object stamp, str target, str source, const double* v):
    """The lookup result: ``TransformStamped(Header(stamp, target), source,
    Transform(Vector3(v[0:3]), Quaternion(v[3:7])))``, built in C."""
    cdef object vec = _named3(Vector3, PyFloat_FromDouble(v[0]), PyFloat_FromDouble(v[1]),
                              PyFloat_FromDouble(v[2]))
    PyObject_GC_UnTrack(<PyObject*>vec)  # three floats: never part of a reference cycle
    cdef object rot = _named4(Quaternion, v[3], v[4], v[5], v[6])
    return _named3(
        TransformStamped, _named(Header, stamp, target), source, _named(Transform, vec, rot)
    )


cdef extern from *:
    """
    /* Reusing a result in place relies on a reference count of 1 meaning "no one else
       holds it", which free-threaded builds do not promise. */
    #ifdef Py_GIL_DISABLED
    #define TFBUS_REUSE_RESULTS 0
    #else
    #define TFBUS_REUSE_RESULTS 1
    #endif
    """
    const bint TFBUS_REUSE_RESULTS


cdef extern from "Python.h":
    ctypedef struct PyFloatObject:
        double ob_fval
    Py_ssize_t _refcnt "Py_REFCNT" (PyObject* o)
    PyObject* _type_of "Py_TYPE" (PyObject* o)
    PyObject* _item "PyTuple_GET_ITEM" (PyObject* p, Py_ssize_t i)
    void _set_item "PyTuple_SET_ITEM" (PyObject* p, Py_ssize_t i, PyObject* o)
    PyObject* _list_item "PyList_GET_ITEM" (PyObject* p, Py_ssize_t i)
    void _list_set "PyList_SET_ITEM" (PyObject* p, Py_ssize_t i, PyObject* o)
    void _incref "Py_INCREF" (PyObject* o)
    void _decref "Py_DECREF" (PyObject* o)


cdef inline Py_ssize_t _seq_len(object seq) noexcept:
    """``len(seq)`` of a list or a tuple (exactly those types)."""
    if type(seq) is list:
        return PyList_GET_SIZE(seq)
    return PyTuple_GET_SIZE(seq)


cdef object _touched(list ids):
    """``TouchedFrames(ids)`` without its Python-level ``__init__`` (one slot, set here)."""
    cdef object touched = <object>PyType_GenericAlloc(<PyTypeObject*>TouchedFrames, 0)
    Py_DECREF(touched)
    PyObject_GenericSetAttr(touched, "_ids", ids)
    return touched


cdef inline void _list_put(PyObject* lst, Py_ssize_t i, PyObject* value) noexcept:
    """``lst[i] = value`` for an index in range (a new reference to ``value``); nothing
    to do when it holds that object already (a refilled list of a steady stream)."""
    cdef PyObject* old = _list_item(lst, i)
    if old == value:
        return
    _incref(value)
    _list_set(lst, i, value)
    _decref(old)


cdef inline bint _sole_floats(PyObject* tup, Py_ssize_t n) noexcept:
    """Whether each of the ``n`` items of ``tup`` is a float held by ``tup`` alone."""
    cdef Py_ssize_t k
    cdef PyObject* f
    for k in range(n):
        f = _item(tup, k)
        if _refcnt(f) != 1 or _type_of(f) != <PyObject*>float:
            return False
    return True


cdef inline void _put(PyObject* tup, Py_ssize_t i, object value) noexcept:
    """Item ``i`` of a tuple held here alone := ``value``."""
    cdef PyObject* old = _item(tup, i)
    _incref(<PyObject*>value)
    _set_item(tup, i, <PyObject*>value)
    _decref(old)


cdef object _restamp(list memo, size_t slot, object stamp, str target, str source,
                     const double* v):
    """:func:`_stamped`, in the objects of the result the memo slot holds when nothing
    else does (no caller kept it, nor any part of it): the slot is about to drop it, so
    no one can see it change (CPython's zip and enumerate reuse their result tuples on
    the same rule). Saves allocating and freeing 12 objects per never-repeated lookup
    whose result is dropped after use; otherwise a new result."""
    cdef PyObject* old = _list_item(<PyObject*>memo, slot)
    cdef PyObject* header
    cdef PyObject* tf
    cdef PyObject* vec
    cdef PyObject* rot
    cdef Py_ssize_t k
    if not TFBUS_REUSE_RESULTS or _refcnt(old) != 1 or _type_of(old) != <PyObject*>TransformStamped:
        return _stamped(stamp, target, source, v)
    header = _item(old, 0)
    tf = _item(old, 2)
    if _refcnt(header) != 1 or _refcnt(tf) != 1:
        return _stamped(stamp, target, source, v)
    vec = _item(tf, 0)
    rot = _item(tf, 1)
    if (_refcnt(vec) != 1 or _refcnt(rot) != 1 or not _sole_floats(vec, 3)
            or not _sole_floats(rot, 4)):
        return _stamped(stamp, target, source, v)
    for k in range(3):
        (<PyFloatObject*>_item(vec, k)).ob_fval = v[k]
    for k in range(4):
        (<PyFloatObject*>_item(rot, k)).ob_fval = v[3 + k]
    _put(header, 0, stamp)
    _put(header, 1, target)
    _put(old, 1, source)
    return <object>old


cdef bint _plain_values(object tf) noexcept:
    """Whether ``tf`` is a ``Transform`` of a ``Vector3`` and a ``Quaternion`` of the
    message classes themselves (no subclass) holding seven ``float``s: the values' part
    of the common form of a transform (``_plain_transform``; the compiled ROS 1 writer's
    test)."""
    cdef object tr, rot
    cdef Py_ssize_t k
    if type(tf) is not Transform or len(<tuple>tf) != 2:
        return False
    tr = (<tuple>tf)[0]
    rot = (<tuple>tf)[1]
    if type(tr) is not Vector3 or len(<tuple>tr) != 3:
        return False
    if type(rot) is not Quaternion or len(<tuple>rot) != 4:
        return False
    for k in range(3):
        if type((<tuple>tr)[k]) is not float:
            return False
    for k in range(4):
        if type((<tuple>rot)[k]) is not float:
            return False
    return True


cdef bint _plain_stamped(object ts) noexcept:
    """``CoreBase._plain_transform``'s test (see it)."""
    cdef object header, tf, tr, rot, parent, child
    cdef double x, y, z, qx, qy, qz, qw, s
    if type(ts) is not TransformStamped or len(<tuple>ts) != 3:
        return False
    header = (<tuple>ts)[0]
    child = (<tuple>ts)[1]
    tf = (<tuple>ts)[2]
    if type(header) is not Header or len(<tuple>header) != 2:
        return False
    if not _plain_values(tf):
        return False
    tr = (<tuple>tf)[0]
    rot = (<tuple>tf)[1]
    parent = (<tuple>header)[1]
    if type((<tuple>header)[0]) is not Time or type(parent) is not str or type(child) is not str:
        return False
    if (not len(<str>parent) or not len(<str>child)
            or PyUnicode_READ_CHAR(parent, 0) == 47 or PyUnicode_READ_CHAR(child, 0) == 47
            or parent == child):
        return False
    x = (<tuple>tr)[0]
    y = (<tuple>tr)[1]
    z = (<tuple>tr)[2]
    qx = (<tuple>rot)[0]
    qy = (<tuple>rot)[1]
    qz = (<tuple>rot)[2]
    qw = (<tuple>rot)[3]
    s = x + y + z
    if s - s != 0.0:  # NaN or ±Inf anywhere makes the sum non-finite
        return False
    return fabs(qw * qw + qx * qx + qy * qy + qz * qz - 1.0) < 0.01  # False for NaN


cdef object _message_of(object ts):
    """``TFMessage((ts,))``, the message's tuple allocated by the type (what
    ``tuple.__new__`` does for a subclass, minus building and copying its argument)."""
    cdef tuple transforms = (ts,)
    cdef PyObject* p = (<PyTypeObject*>TFMessage).tp_alloc(<PyTypeObject*>TFMessage, 1)
    cdef object message
    if p == NULL:
        raise MemoryError()
    message = <object>p
    Py_DECREF(message)  # tp_alloc's reference, now owned by ``message``
    Py_INCREF(transforms)
    PyTuple_SET_ITEM(message, 0, transforms)
    return message


cdef object _time_of(int64_t ns):
    """``Time.from_ns(ns)`` for a valid ns, without re-validating it: the instance from
    the type's ``tp_alloc`` (what ``object.__new__`` does, minus looking up and calling
    it), its ``_ns`` slot set through the generic setattr (the slot's descriptor)."""
    cdef PyObject* p = (<PyTypeObject*>Time).tp_alloc(<PyTypeObject*>Time, 0)
    cdef object t = <object>p
    Py_DECREF(t)  # tp_alloc's reference, now owned by ``t``
    PyObject_GenericSetAttr(t, "_ns", ns)
    return t


cdef extern from "Python.h":
    ctypedef struct PyMemberDef:
        int type
        Py_ssize_t offset
    ctypedef struct PyMemberDescrObject:
        PyMemberDef* d_member

# A member of type T_OBJECT_EX (Py_T_OBJECT_EX from 3.12 on; 16 in every CPython).
cdef int _T_OBJECT_EX = 16


cdef frozenset _NO_FRAMES = frozenset()

cdef Py_ssize_t _NS_OFFSET = -1
"""Where a ``Time``'s ``_ns`` slot lies in the object (from the slot's member descriptor;
-1 if it is not a plain object slot): ``_stamp_ns`` reads it without the attribute
lookup."""
_ns_slot = Time.__dict__.get("_ns")
if type(_ns_slot).__name__ == "member_descriptor":
    if (<PyMemberDescrObject*><PyObject*>_ns_slot).d_member.type == _T_OBJECT_EX:
        _NS_OFFSET = (<PyMemberDescrObject*><PyObject*>_ns_slot).d_member.offset


cdef Py_ssize_t _IDS_OFFSET = -1
"""Where a ``TouchedFrames``' ``_ids`` slot lies in the object (as ``_NS_OFFSET``; -1:
read and set through the attribute): a kept batch result is refilled in place."""
_ids_slot = TouchedFrames.__dict__.get("_ids")
if type(_ids_slot).__name__ == "member_descriptor":
    if (<PyMemberDescrObject*><PyObject*>_ids_slot).d_member.type == _T_OBJECT_EX:
        _IDS_OFFSET = (<PyMemberDescrObject*><PyObject*>_ids_slot).d_member.offset


cdef inline int64_t _stamp_ns(object stamp) except? -1:
    """``stamp._ns`` of a ``Time`` (or subclass): the slot read in place for ``Time``
    itself, the attribute otherwise."""
    cdef PyObject* ns
    if _NS_OFFSET >= 0 and type(stamp) is Time:
        ns = (<PyObject**>((<char*><PyObject*>stamp) + _NS_OFFSET))[0]
        if ns != NULL:
            return <int64_t><object>ns
    return stamp._ns


# Validation outcomes of an inserted transform (beyond the cache's OK / OLD / REPEATED).
INVALID = 3
"""``CoreBase._store``: the transform breaks one of tf2's rules (setTransformImpl)."""

# Query failures beyond tf2's codes: a bad argument (empty or '/'-prefixed id).
INVALID_ARGUMENT = 4
UNKNOWN_FRAME = 5


cdef inline str _as_str(object value):
    """A frame id as the exact ``str`` it is (``numpy.str_`` or any ``str`` subclass is
    accepted as its string value); None for anything that is not a string."""
    if type(value) is str:
        return <str>value
    if isinstance(value, str):
        return str.__str__(value)
    return None


cdef inline bint _slashed(str frame_id) noexcept:
    """Whether ``frame_id`` starts with '/' (tf2 ``stripSlash`` strips one)."""
    return PyUnicode_GET_LENGTH(frame_id) != 0 and PyUnicode_READ_CHAR(frame_id, 0) == 47


cdef str _show(object value):
    """``repr`` of a bad value for an error message, bounded in length."""
    cdef str text
    try:
        text = repr(value)
    except Exception:
        text = f"<{type(value).__name__}>"
    return text if len(text) <= 80 else text[:77] + "..."


cdef inline double _number(object value, str field) except? -1.0:
    """A transform component as a double; anything but a real number (bool, None, str,
    an int beyond double range, ...) is an InvalidArgumentException naming the field."""
    if type(value) is float:
        return <double>value
    if not isinstance(value, (bool, np.bool_, str, bytes, complex)) and value is not None:
        try:
            return float(value)
        except (OverflowError, TypeError, ValueError):
            pass
    raise InvalidArgumentException(f"{field} must be a real number, got {_show(value)}")


cdef tuple _FIELDS = (
    "transform.translation.x",
    "transform.translation.y",
    "transform.translation.z",
    "transform.rotation.x",
    "transform.rotation.y",
    "transform.rotation.z",
    "transform.rotation.w",
)


cdef tuple _bad_id(str frame_id, int which):
    """The failure tuple of a query argument that is not a known frame (tf2
    ``validateFrameId``): empty or '/'-prefixed ids are invalid, others unknown."""
    if not frame_id or frame_id[0] == "/":
        return (INVALID_ARGUMENT, which)
    return (UNKNOWN_FRAME, which)


cdef int _climb(list caches, int frame, int stop, int early, int64_t time, double* acc,
                int* reached) except -1:
    """One half of tf2's ``walkToTopParent``: walk up from ``frame`` gathering each link
    at ``time`` and accumulating ``frame -> current`` into ``acc``.

    Stops at ``stop`` (not gathered), at a frame without a link, at a link with no data
    (CLIMB_FAILED, ``reached`` = the failing frame), or at ``early`` once its link
    gathered (CLIMB_EARLY; that link is not accumulated). ``reached`` is the frame where
    the climb ended.
    """
    cdef double st[7]
    cdef int parent = 0
    cdef int depth = 0
    cdef bint first = True
    cdef object obj
    _identity(acc)
    while frame != stop:
        obj = _link(caches, frame)
        if obj is None:
            break
        if (<Link>obj).c_gather(time, st, &parent) != G_OK or parent == 0:
            reached[0] = frame
            return CLIMB_FAILED
        if frame == early:
            reached[0] = frame
            return CLIMB_EARLY
        if first:
            memcpy(acc, st, 7 * sizeof(double))
            first = False
        else:
            _accumulate(acc, st)
        frame = parent
        depth += 1
        if depth > C_MAX_DEPTH:
            reached[0] = frame
            return CLIMB_LOOP
    reached[0] = frame
    return CLIMB_STOPPED


cdef int _climb_policy(list caches, int frame, int stop, int early, int64_t time, int mode,
                       int64_t before, int64_t after, double* acc, int* reached,
                       int* frames, int64_t* stamps, Py_ssize_t* count) except -1:
    """``_climb`` with each link's sample picked by a lookup policy (``Link.c_pick``);
    records the child frame and sample stamp of every accumulated link in ``frames`` /
    ``stamps`` (room for ``C_MAX_DEPTH + 2``), their number in ``count``."""
    cdef double st[7]
    cdef int parent = 0
    cdef int depth = 0
    cdef int64_t used = 0
    cdef bint first = True
    cdef object obj
    _identity(acc)
    count[0] = 0
    while frame != stop:
        obj = _link(caches, frame)
        if obj is None:
            break
        if (<Link>obj).c_pick(time, mode, before, after, st, &parent, &used) != G_OK \
                or parent == 0:
            reached[0] = frame
            return CLIMB_FAILED
        if frame == early:
            reached[0] = frame
            return CLIMB_EARLY
        frames[count[0]] = frame
        stamps[count[0]] = used
        count[0] += 1
        if first:
            memcpy(acc, st, 7 * sizeof(double))
            first = False
        else:
            _accumulate(acc, st)
        frame = parent
        depth += 1
        if depth > C_MAX_DEPTH:
            reached[0] = frame
            return CLIMB_LOOP
    reached[0] = frame
    return CLIMB_STOPPED


cdef inline list _spare_ids(CoreBase core, Py_ssize_t n):
    """The id list of the batch result the core kept (``_batch``), to be filled in again,
    when nothing but the core holds that result, its TouchedFrames or the list
    (reference counts of 1) and the list has ``n`` items; else None."""
    cdef PyObject* p
    cdef PyObject* t
    cdef PyObject* q
    if not TFBUS_REUSE_RESULTS or core._batch is None:
        return None
    p = <PyObject*>core._batch
    if _refcnt(p) != 1:
        return None
    t = _item(p, 3)
    if _refcnt(t) != 1 or _type_of(t) != <PyObject*>TouchedFrames:
        return None
    if _IDS_OFFSET < 0:
        return None
    q = (<PyObject**>((<char*>t) + _IDS_OFFSET))[0]
    # One reference: the TouchedFrames' slot.
    if q != NULL and _type_of(q) == <PyObject*>list and _refcnt(q) == 1:
        if PyList_GET_SIZE(<object>q) == n:
            return <list>q
    return None


cdef inline object _batch_result_of(CoreBase core, Py_ssize_t stored, list ids,
                                    bint relinked):
    """``BatchResult(stored, 0, [], TouchedFrames(ids), relinked)``. The core keeps the
    last result it built (``_batch``); when nothing but the core holds it, its
    TouchedFrames or its ``errors`` list (reference counts of 1, ``errors`` still empty)
    it is filled in again and returned, instead of three objects being freed and
    allocated per batch (the lookup memo reuses a dropped result the same way)."""
    cdef PyObject* p
    cdef PyObject* t
    cdef PyObject* e
    cdef PyObject* q
    cdef PyObject** slot
    cdef object r
    if TFBUS_REUSE_RESULTS and core._batch is not None:
        p = <PyObject*>core._batch
        if _refcnt(p) == 1:
            t = _item(p, 3)
            e = _item(p, 2)
            if (_refcnt(t) == 1 and _type_of(t) == <PyObject*>TouchedFrames
                    and _refcnt(e) == 1 and _type_of(e) == <PyObject*>list
                    and PyList_GET_SIZE(<object>e) == 0):
                if _IDS_OFFSET >= 0:
                    slot = <PyObject**>((<char*>t) + _IDS_OFFSET)
                    if slot[0] != <PyObject*>ids:
                        q = slot[0]
                        _incref(<PyObject*>ids)
                        slot[0] = <PyObject*>ids
                        if q != NULL:
                            _decref(q)
                else:
                    PyObject_GenericSetAttr(<object>t, "_ids", ids)
                _put(p, 0, stored)
                _put(p, 4, relinked)
                return <object>p
    r = _named5(BatchResult, stored, 0, [], _touched(ids), relinked)
    core._batch = r
    return r


cdef class CoreBase:
    """Frame table and hot paths of :class:`tfbus.core.BufferCore` (which subclasses it).

    Inserts and queries return codes and data, and ``tfbus.core`` turns them into tf2's
    messages, exceptions and log lines; the calls into the subclass are
    ``set_transform``'s (and ``set_transform_static``'s) for a transform not stored
    (``_not_stored``) and, with waits to settle (``_follow_waits``), for the waits the
    insert did not settle (``_recheck_rest``); ``set_transforms``' for a batch with a
    refusal or an invalid item (``_batch_result``) and for the waits it did not settle.

    Read-only internals (for white-box tests and the batch kernel, never written from
    Python): ``_frame_ids`` (frame id → int id; 0 is tf2's ``NO_PARENT``), ``_frame_names``
    (int id → frame id), ``_caches`` (int id → link or None), ``_authority`` (int id →
    authority of its last stored transform) and ``_generation`` (bumped by every insert
    attempt and by ``clear``). Python code uses the public methods: ``clear``,
    ``get_frame_names``, ``frame_exists``, ``parent_of``, ``link_info``,
    ``extrapolation_detail``, ``common_time``.
    """

    # The lookup memo, direct-mapped: slot -> the last result stored there, the time
    # asked and the generation it is valid for (no key tuple, no dict: a never-repeated
    # query pays a few compares and one list store).
    # What the last ``_insert_one`` did, beyond its code (read by ``_store`` and
    # ``_store_one`` right after it; no list per transform): the stripped ids, the stamp,
    # the values (for INVALID only) and whether the tree's shape may have changed.

    def __cinit__(self, *args, **kwargs):
        cdef int k
        self._frame_ids = {"NO_PARENT": 0}
        self._frame_names = ["NO_PARENT"]
        self._caches = [None]
        self._authority = {}
        self._generation = 0
        self._cache_ns = 0
        self._replace_repeated = False
        self._free = []
        self._refs = [0]
        self._lparents = [None]
        self._heap = []
        self._newest = 0
        self._expiring = False
        self._expire_ns = 0
        self._expire_every = 0
        self._expire_due = INT64_MAX
        self._frames_expired = 0
        self._waits = None
        self._batch = None
        self._settled = None
        self._memo = [None] * MEMO_SIZE
        for k in range(MEMO_SIZE):
            self._memo_gen[k] = -1
            self._memo_t[k] = 0

    @property
    def cache_time_ns(self):
        """The history kept per dynamic link, nanoseconds (the one copy: every link is
        created with it; read-only)."""
        return self._cache_ns

    def _set_cache_time_ns(self, ns):
        """Set the cache time (ns); only before the first insert (``BufferCore.__init__``)."""
        if len(self._frame_names) > 1:
            raise RuntimeError("cache_time is fixed once transforms are stored")
        self._cache_ns = min(ns, INT64_MAX)

    @property
    def replace_repeated(self):
        """Whether a transform whose stamp equals the newest sample of its link replaces
        that sample (``on_repeat="replace"``) instead of being refused as
        TF_REPEATED_DATA (tf2's rule; read-only)."""
        return self._replace_repeated

    def _set_replace_repeated(self, replace):
        """Set :attr:`replace_repeated`; only before the first insert
        (``BufferCore.__init__``)."""
        if len(self._frame_names) > 1:
            raise RuntimeError("on_repeat is fixed once transforms are stored")
        self._replace_repeated = replace

    cdef object _register(self, str frame_id):
        cdef object fid
        if self._free:  # the id of a forgotten frame (its link and counts already reset)
            fid = self._free.pop()
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

    cdef int _name_parent(self, object cid, object pid) except -1:
        """Record that the link of ``cid`` named ``pid`` as its parent (once per pair):
        ``pid`` stays known while that link does."""
        cdef object ps = self._lparents[cid]
        if ps is None:
            self._lparents[cid] = (pid,)
        elif pid in <tuple>ps:
            return 0
        else:
            self._lparents[cid] = (<tuple>ps) + (pid,)
        self._refs[pid] += 1
        return 0

    cdef int _unregister(self, object fid) except -1:
        """Forget frame ``fid`` (no link, no link naming it): its id becomes unknown and
        its number free for the next new frame."""
        del self._frame_ids[self._frame_names[fid]]
        self._frame_names[fid] = ""
        self._authority.pop(fid, None)
        self._free.append(fid)
        return 0

    # ------------------------------------------------------------------ expiry

    def _forget(self, int64_t older_than):
        """Remove every dynamic link whose newest sample is older than ``older_than``
        (ns, strictly: ``newest < older_than``), as tf2 has no call for (ros/geometry2
        #409, #239). ``BufferCore.forget`` documents the rule; returns the number of
        links removed."""
        return self._cforget(older_than)

    cdef Py_ssize_t _cforget(self, int64_t older_than) except -1:
        """``_forget`` (what ``expire_after`` calls, never a subclass's override)."""
        cdef list heap = self._heap
        cdef list caches = self._caches
        cdef list refs = self._refs
        cdef Py_ssize_t removed = 0
        cdef int64_t newest
        cdef object fid, cache, ps, p
        while heap and <int64_t>(<tuple>heap[0])[0] < older_than:
            fid = (<tuple>heappop(heap))[1]
            cache = caches[fid]
            if fid == 0 or not isinstance(cache, TimeCache):
                continue
            (<Link>cache).c_latest(&newest)
            if newest >= older_than:
                heappush(heap, (newest, fid))
                continue
            caches[fid] = None
            self._authority.pop(fid, None)
            ps = self._lparents[fid]
            self._lparents[fid] = None
            if ps is not None:
                for p in <tuple>ps:
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
    def frames_expired(self):
        """How many links ``expire_after`` has removed (``BufferCore.forget`` called
        directly is not counted)."""
        return self._frames_expired

    @property
    def expire_after_ns(self):
        """``expire_after``'s age limit in ns; 0 when frames never expire."""
        return self._expire_ns if self._expiring else 0

    def _set_expiry(self, int64_t after_ns, int64_t every_ns):
        """Remove, as data arrives, the links whose newest sample is more than
        ``after_ns`` older than the newest dynamic stamp stored, checked whenever that
        stamp has advanced ``every_ns`` since the last check."""
        self._expire_ns = after_ns
        self._expire_every = every_ns
        self._expiring = True
        self._expire_due = (INT64_MAX if self._newest > INT64_MAX - every_ns
                            else self._newest + every_ns)

    cdef int _expire(self) except -1:
        """``expire_after``'s check (the newest stamp reached ``_expire_due``)."""
        if not self._expiring:
            self._expire_due = INT64_MAX
            return 0
        self._frames_expired += self._cforget(self._newest - self._expire_ns)
        self._expire_due = (INT64_MAX if self._newest > INT64_MAX - self._expire_every
                            else self._newest + self._expire_every)
        return 0

    # ------------------------------------------------------------------ insert

    cdef int _insert_one(self, object ts, str authority, bint is_static) except -1:
        """``BufferCore::setTransformImpl``: check, register frames, store.

        Returns the cache's C_OK / C_OLD_DATA / C_REPEATED_DATA, or INVALID (a tf2 rule
        is broken). What it did beyond the code is left in ``_last_parent``,
        ``_last_child`` (stripped ids), ``_last_stamp`` (ns; not for INVALID),
        ``_last_values`` (the 7 values, INVALID only) and ``_last_relinked``. A field of
        the wrong type raises InvalidArgumentException naming it; nothing is stored or
        registered before every check has passed (no half-stored frame)."""
        cdef object header, tf, tr, rot, stamp_obj, cid, pid, cache
        cdef str child, parent
        cdef double v[7]
        cdef double norm2
        cdef int64_t stamp, old_stamp
        cdef int code, k, old_parent, pi
        cdef Py_ssize_t ci
        cdef bint same
        header = (<tuple>ts)[0]
        tf = (<tuple>ts)[2]
        if not isinstance(header, Header):
            raise InvalidArgumentException(f"header must be a Header, got {_show(header)}")
        if not isinstance(tf, Transform):
            raise InvalidArgumentException(f"transform must be a Transform, got {_show(tf)}")
        tr = (<tuple>tf)[0]
        rot = (<tuple>tf)[1]
        if not (isinstance(tr, tuple) and len(<tuple>tr) == 3):
            raise InvalidArgumentException(
                f"transform.translation must be a Vector3, got {_show(tr)}")
        if not (isinstance(rot, tuple) and len(<tuple>rot) == 4):
            raise InvalidArgumentException(
                f"transform.rotation must be a Quaternion, got {_show(rot)}")
        parent = _as_str((<tuple>header)[1])
        if parent is None:
            raise InvalidArgumentException(
                f"header.frame_id must be a str, got {_show((<tuple>header)[1])}")
        child = _as_str((<tuple>ts)[1])
        if child is None:
            raise InvalidArgumentException(
                f"child_frame_id must be a str, got {_show((<tuple>ts)[1])}")
        stamp_obj = (<tuple>header)[0]
        if not isinstance(stamp_obj, Time):
            raise InvalidArgumentException(f"header.stamp must be a Time, got {_show(stamp_obj)}")
        for k in range(3):
            v[k] = _number((<tuple>tr)[k], _FIELDS[k])
        for k in range(4):
            v[3 + k] = _number((<tuple>rot)[k], _FIELDS[3 + k])
        if _slashed(parent):
            parent = parent[1:]
        if _slashed(child):
            child = child[1:]
        self._last_parent = parent
        self._last_child = child
        # tf2's order (setTransformImpl: w² + x² + y² + z²): it decides cases at the limit.
        norm2 = v[6] * v[6] + v[3] * v[3] + v[4] * v[4] + v[5] * v[5]
        # Self transform: two known ids are the same frame exactly when they map to the
        # same id object (no string comparison); a known and an unknown id never are.
        cid = self._frame_ids.get(child)
        pid = self._frame_ids.get(parent)
        if cid is not None:
            same = cid is pid
        else:
            same = pid is None and child == parent
        # `v - v == 0` fails for NaN and ±Inf alike; the norm test fails for NaN too.
        if (
            same
            or not child
            or not parent
            or v[0] - v[0] != 0.0
            or v[1] - v[1] != 0.0
            or v[2] - v[2] != 0.0
            or not fabs(norm2 - 1.0) < 0.01
        ):
            self._last_values = (v[0], v[1], v[2], v[3], v[4], v[5], v[6])
            return C_INVALID
        stamp = _stamp_ns(stamp_obj)
        self._last_stamp = stamp
        self._generation += 1
        if cid is None:
            cid = self._register(child)
        ci = <Py_ssize_t>cid
        cache = self._caches[ci]
        if cache is None:
            if is_static:
                cache = StaticCache()
            else:
                cache = TimeCache(self._cache_ns, self._replace_repeated)
                heappush(self._heap, (stamp, cid))
            self._caches[ci] = cache
        if pid is None:
            pid = self._register(parent)
        if not is_static and stamp > self._newest:
            self._newest = stamp
        pi = <int>pid
        old_parent = (<Link>cache).c_latest(&old_stamp)
        if old_parent != pi:
            self._name_parent(cid, pid)
        code = (<Link>cache).c_insert(stamp, pi, v)
        # The tree's shape may have changed: a new or emptied link, another parent, or a
        # link that keeps one parent per sample.
        self._last_relinked = False
        if code == C_OK:
            if old_parent != pi:
                self._last_relinked = True
            elif type(cache) is TimeCache and (<TimeCache>cache)._pa != NULL:
                self._last_relinked = True
            # The link's authority: stored only when it is another string object (a
            # stream from one sender re-stores nothing).
            if PyDict_GetItem(self._authority, cid) != <PyObject*>authority:
                self._authority[cid] = authority
        return code

    cdef object _problem(self, int code):
        """What ``_store_one`` reports for a transform ``_insert_one`` did not store."""
        if code == C_INVALID:
            return (INVALID, self._last_parent, self._last_child, self._last_values)
        return (code, self._last_child, self._last_stamp)

    def set_transform(self, transform, str authority="default"):
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

        The core's method, called with no Python frame in between (``BufferCore``
        inherits it); a transform not stored goes to the subclass's ``_not_stored``
        (the log line, or the exception). With waits to settle (``_follow_waits``), a
        stored transform settles them here (``_settle``), and what is left goes to the
        subclass's ``_recheck_rest(rest, relinked)``.
        """
        # The body of set_transform_static too, not a shared helper: gcc 12 at -O2 keeps
        # such a helper out of line, and an insert into a BufferCore then costs 5-10 %
        # more (measured A/B, benchmarks/bench_check.py's rows and a 300-insert loop).
        cdef int code
        cdef object rest
        if not isinstance(transform, TransformStamped):
            raise TypeError(f"expected TransformStamped, got {type(transform).__name__}")
        code = self._insert_one(transform, authority, False)
        if self._newest >= self._expire_due:
            self._expire()
        if code == C_OK:
            if self._waits:
                rest = self._csettle(self._waits, None)
                if rest is not None:
                    self._recheck_rest(rest, self._last_relinked)
            return True
        self._not_stored(self._problem(code), authority)
        return False

    def set_transform_static(self, transform, str authority="default"):
        """Store a static transform: valid at all times, overwritten by every later send
        (tf2 ``setTransform(..., is_static=true)``). Whether a link is static is fixed by
        its first accepted transform, as in tf2.

        Returns and raises as :meth:`set_transform`.
        """
        # set_transform's body (see there), with is_static True.
        cdef int code
        cdef object rest
        if not isinstance(transform, TransformStamped):
            raise TypeError(f"expected TransformStamped, got {type(transform).__name__}")
        code = self._insert_one(transform, authority, True)
        if self._newest >= self._expire_due:
            self._expire()
        if code == C_OK:
            if self._waits:
                rest = self._csettle(self._waits, None)
                if rest is not None:
                    self._recheck_rest(rest, self._last_relinked)
            return True
        self._not_stored(self._problem(code), authority)
        return False

    def _store(self, transforms, str authority, bint is_static):
        """Store every :class:`~tfbus.messages.TransformStamped` of ``transforms``, in
        order; one bad item never stops the others. Calls nothing back.

        Returns the :class:`~tfbus.core.results.BatchResult` itself when nothing was
        refused and nothing was invalid (the common case: no Python code runs after this
        one call). Else the plain tuple ``(stored, errors, touched, relinked, refusals)``
        for ``BufferCore`` to turn into tf2's messages and log lines:

        * ``stored``: how many were stored;
        * ``refusals``: ``[(code, child, stamp ns)]`` for each refused by its cache
          (``OLD_DATA`` / ``REPEATED_DATA``);
        * ``errors``: ``[(index, problem)]``, ``problem`` either an exception
          (InvalidArgumentException for a field of the wrong type, TypeError for an item
          that is not a TransformStamped) or ``(parent, child, values)`` for a transform
          that breaks a tf2 rule (the caller builds tf2's message);
        * ``touched``: a :class:`~tfbus.core.results.TouchedFrames` of the (stripped)
          child and parent ids of every stored transform (recorded in a list here, made a
          set only when asked);
        * ``relinked``: whether a stored transform may have changed the tree's shape.
        """
        return self._cstore(transforms, authority, is_static)

    cdef object _cstore(self, object transforms, str authority, bint is_static):
        """:meth:`_store`, callable from C (``set_transforms``'s body). A list or tuple is
        read by index and its ids recorded in a list made at its size (no growth); one
        ``try`` covers the run of items up to one that raises (none, usually)."""
        cdef Py_ssize_t stored = 0, i = 0, k = 0
        cdef list refusals = None
        cdef list errors = None
        cdef list ids
        cdef bint relinked = False, is_list
        cdef int code
        cdef object ts, seq
        if type(transforms) is list or type(transforms) is tuple:
            seq = transforms
        else:
            seq = None
        if seq is None:
            ids = []
            for ts in transforms:
                try:
                    if not isinstance(ts, TransformStamped):
                        raise TypeError(f"expected TransformStamped, got {type(ts).__name__}")
                    code = self._insert_one(ts, authority, is_static)
                except Exception as exc:
                    if errors is None:
                        errors = []
                    errors.append((i, exc))
                else:
                    if code == C_OK:
                        stored += 1
                        ids.append(self._last_child)
                        ids.append(self._last_parent)
                        if self._last_relinked:
                            relinked = True
                    elif code == C_INVALID:
                        if errors is None:
                            errors = []
                        errors.append(
                            (i, (self._last_parent, self._last_child, self._last_values)))
                    else:
                        if refusals is None:
                            refusals = []
                        refusals.append((code, self._last_child, self._last_stamp))
                i += 1
        else:
            # The items are read again each time (the list may change size while an
            # item's conversion runs Python code, as a for loop over it would see).
            ids = _spare_ids(self, 2 * _seq_len(seq))
            if ids is None:
                ids = [None] * (2 * _seq_len(seq))
            is_list = type(seq) is list
            while i < _seq_len(seq):
                try:
                    while i < _seq_len(seq):
                        if is_list:
                            ts = <object>_list_item(<PyObject*>seq, i)
                        else:
                            ts = <object>_item(<PyObject*>seq, i)
                        if not isinstance(ts, TransformStamped):
                            raise TypeError(
                                f"expected TransformStamped, got {type(ts).__name__}")
                        code = self._insert_one(ts, authority, is_static)
                        if code == C_OK:
                            stored += 1
                            if k < len(ids):  # a slot made for it (None until then)
                                _list_put(<PyObject*>ids, k, <PyObject*>self._last_child)
                                _list_put(<PyObject*>ids, k + 1, <PyObject*>self._last_parent)
                            else:  # the list grew while it was read
                                ids.append(self._last_child)
                                ids.append(self._last_parent)
                            k += 2
                            if self._last_relinked:
                                relinked = True
                        elif code == C_INVALID:
                            if errors is None:
                                errors = []
                            errors.append(
                                (i, (self._last_parent, self._last_child, self._last_values)))
                        else:
                            if refusals is None:
                                refusals = []
                            refusals.append((code, self._last_child, self._last_stamp))
                        i += 1
                except Exception as exc:
                    if errors is None:
                        errors = []
                    errors.append((i, exc))
                    i += 1
            if k < len(ids):
                ids = ids[:k]
        if self._newest >= self._expire_due:
            self._expire()
        if errors is None and refusals is None:
            return _batch_result_of(self, stored, ids, relinked)
        return (stored, [] if errors is None else errors, _touched(ids), relinked,
                [] if refusals is None else refusals)

    def set_transforms(self, transforms, str authority="default", is_static=False):
        """Store a batch of transforms (a ``TFMessage``'s worth) in one call: what the
        listener uses. Per transform it is cheaper than a loop of :meth:`set_transform`
        from about five transforms a call on and within a few percent of it at two; one
        transform a call pays for the :class:`~tfbus.core.results.BatchResult` beside the
        insert, about 1.2 to 1.4 times the loop's time (``make bench-check`` prints the
        ratio by message size).

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

        The core's method (``BufferCore`` and ``Buffer`` inherit it: no Python frame
        between the caller and the inserts). A batch with a refusal or an invalid item
        gets its result from the subclass's ``_batch_result`` (log lines, tf2's
        exceptions). With waits to settle (``_follow_waits``), the waits on the ids the
        batch touched are settled here, once per batch (``_settle``), and what is left
        goes to the subclass's ``_recheck_rest(rest, relinked)``.
        """
        cdef object r, rest, touched
        r = self._cstore(transforms, authority, is_static)
        if type(r) is not BatchResult:  # a refusal or an invalid item: log lines, exceptions
            r = self._batch_result(r, authority)
        if self._waits:
            touched = (<tuple>r)[3]
            # The ids recorded by the insert (repeats allowed; no set built for them).
            rest = self._csettle(
                self._waits, touched._ids if type(touched) is TouchedFrames else touched)
            if rest is not None:
                self._recheck_rest(rest, (<tuple>r)[4])
        return r

    def _store_one(self, ts, str authority, bint is_static):
        """One transform, as ``_store`` would store it (``BufferCore.set_transform``'s
        path: no list, set or tuple on success). Calls nothing back.

        Returns True when stored; else what ``_store`` reports for it: ``(OLD_DATA |
        REPEATED_DATA, child, stamp ns)`` for a refusal by the cache, ``(INVALID, parent,
        child, values)`` for a transform that breaks a tf2 rule.

        Raises:
            TypeError: ``ts`` is not a TransformStamped.
            InvalidArgumentException: a field of the wrong type (named).
        """
        cdef int code
        if not isinstance(ts, TransformStamped):
            raise TypeError(f"expected TransformStamped, got {type(ts).__name__}")
        code = self._insert_one(ts, authority, is_static)
        if self._newest >= self._expire_due:
            self._expire()
        if code == C_OK:
            return True
        return self._problem(code)

    def _last_touched(self):
        """``(child, parent, relinked)`` of the transform ``_store_one`` last stored: the
        (stripped) ids whose lookups may have changed and whether the tree's shape may
        have (what ``_store`` reports per batch); read by ``tfbus.buffer.Buffer`` when
        waits are pending."""
        return self._last_child, self._last_parent, self._last_relinked

    @staticmethod
    def _plain_transform(ts):
        """Whether ``ts`` is a transform every ``set_transform`` accepts, by a quick test
        of its common form: a ``TransformStamped`` of the message classes themselves (no
        subclass), stamp a ``Time``, two different ``str`` ids, neither empty nor
        '/'-prefixed, seven ``float`` values, a finite translation and a quaternion
        whose squared norm (w² + x² + y² + z², tf2's order) is within 0.01 of 1.

        False says only that the quick test does not decide (the broadcaster then asks
        ``set_transform`` itself, the one authority on validity); never raises."""
        return _plain_stamped(ts)

    @staticmethod
    def _message_of_one(ts):
        """The ``TFMessage`` of ``ts`` alone when :meth:`_plain_transform` accepts it
        (made in C: the message's tuple and its one-item tuple of transforms, as
        ``TFMessage((ts,))`` makes them), else None (the broadcaster then checks ``ts``
        and makes the message in Python). What a broadcaster's send of one transform
        needs, in one call; never raises but MemoryError."""
        if not _plain_stamped(ts):
            return None
        return _message_of(ts)

    def _follow_waits(self, dict index, list settled=None):
        """Settle the waits of ``index`` (frame id -> set of waits, the subclass's own
        dict, kept by reference) in every later ``set_transform`` and
        ``set_transform_static`` that stores (see :meth:`_settle`); ``None`` stops.
        ``settled``: the subclass's list (kept by reference) that a settled wait is
        appended to, left in ``index`` for the subclass to remove later (off the
        wake-up's path); None: removed from ``index`` as it is settled."""
        self._waits = index
        self._settled = settled

    def _settle(self, dict index, names):
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
        return self._csettle(index, names)

    cdef object _csettle(self, dict index, object names):
        """:meth:`_settle`, callable from C with no Python call in between."""
        cdef list rest = None
        cdef list settled = self._settled
        cdef set first = None, second = None, union = None
        cdef object ws, waiter, name
        if names is None:
            # the insert's two ids, with no tuple of them
            first = index.get(self._last_child)
            ws = index.get(self._last_parent)
            if first is None:
                if ws is None:
                    return None
                first = <set>ws
            elif ws is not None and ws is not first:
                second = <set>ws
        else:
            for name in names:
                ws = index.get(name)
                if ws is None or ws is first or ws is second:
                    continue
                if first is None:
                    first = <set>ws
                elif second is None:
                    second = <set>ws
                elif union is None:
                    union = set(first)
                    union.update(second)
                    union.update(<set>ws)
                else:
                    union.update(<set>ws)
            if first is None:
                return None
        if union is None and settled is None:
            # Settling a wait edits the index's sets: a copy of them is walked.
            union = set(first)
            if second is not None:
                union.update(second)
        if union is not None:  # a set of its own, which nothing else edits
            for waiter in union:
                rest = self._settle_one(waiter, index, settled, rest)
            return rest
        # With ``settled`` kept nothing edits the index's sets while they are walked (a
        # settled wait stays in them, listed in ``settled``; a wake-up runs no code of
        # anyone's): the sets themselves, no copy; the second's waits that are in the
        # first are taken once.
        for waiter in first:
            rest = self._settle_one(waiter, index, settled, rest)
        if second is not None:
            for waiter in second:
                if waiter not in first:
                    rest = self._settle_one(waiter, index, settled, rest)
        return rest

    cdef list _settle_one(self, object waiter, dict index, list settled, list rest):
        """One wait of :meth:`_csettle`: settled and woken when it is exact and its lookup
        now succeeds; else appended to ``rest`` (made when None) with its failure (or
        None); ``rest`` returned."""
        cdef object exact, out, name, ws, future
        if waiter.result is not None:
            return rest  # settled before, still in the index (``settled``)
        exact = waiter.exact
        if exact is None:
            out = None
        else:
            out = self._cquery((<tuple>exact)[0], (<tuple>exact)[1], (<tuple>exact)[2])
            if type(out) is TransformStamped:  # else a failure tuple
                waiter.result = out
                if settled is not None:
                    settled.append(waiter)
                else:
                    for name in waiter.frames:
                        ws = index.get(name)
                        if ws is not None:
                            (<set>ws).discard(waiter)
                            if not ws:
                                del index[name]
                    waiter.frames = _NO_FRAMES
                future = waiter.future
                if future is None:
                    waiter.wake()
                elif not future.done():
                    future.set_result(None)
                return rest
        if rest is None:
            rest = []
        rest.append((waiter, out))
        return rest

    # ------------------------------------------------------------------ queries

    def _id_status(self, frame_id):
        """0 for a known, queryable frame id; else INVALID_ARGUMENT (not a string, empty,
        '/'-prefixed) or UNKNOWN_FRAME (tf2 ``validateFrameId``)."""
        cdef str name = _as_str(frame_id)
        if name is None:
            return INVALID_ARGUMENT
        if self._frame(name) >= 0:
            return 0
        return _bad_id(name, 0)[0]


    def lookup_transform(self, target_frame, source_frame, time, policy=None):
        """``BufferCore.lookup_transform`` (documented there): the exact lookup entered
        here, with no Python frame between the caller and the walk; a policy lookup, a
        failure or a ``time`` that is not a Time goes on to ``BufferCore``'s
        ``_lookup_by_policy`` / ``_lookup_failed``, which raise tf2's exceptions."""
        cdef object out
        if policy is not None:
            return self._lookup_by_policy(target_frame, source_frame, time, policy)
        try:
            out = self._cquery(target_frame, source_frame, time)
        except AttributeError as err:  # time._ns: not a Time
            return self._lookup_failed(target_frame, source_frame, time, err)
        if type(out) is TransformStamped:
            return out
        return self._lookup_failed(target_frame, source_frame, time, out)

    def _query(self, object target, object source, time):
        """``lookupTransform(target, source, time)`` in one call: the TransformStamped
        (built here, memoised until the next insert or clear), or a failure tuple:

        * ``(INVALID_ARGUMENT, 0 | 1)`` / ``(UNKNOWN_FRAME, 0 | 1)``: the target (0) or
          source (1) id is empty / '/'-prefixed, or unknown;
        * ``(LOOKUP_ERROR, 0)``: a loop; ``(CONNECTIVITY_ERROR, 0)``: two trees;
        * ``(EXTRAPOLATION_ERROR, frame id, time ns, expired)``: the link of that frame has
          no data at the time; ``expired`` when the time is older than the path's latest
          common time minus cache_time (tf2's transformable-request test), i.e. waiting
          cannot help.
        """
        return self._cquery(target, source, time)

    cdef object _cquery(self, object target, object source, object time):
        """:meth:`_query`, callable from C with no Python call in between."""
        cdef int64_t t = (<object>time)._ns
        cdef int64_t used, lct
        cdef int target_id, source_id, err, where = 0, gcode = 0
        cdef double v[7]
        cdef object hit, out, cache
        cdef size_t slot
        cdef bint expired
        cdef Link link
        cdef double st[7]
        cdef int p = 0
        if type(target) is not str:
            target = _as_str(target)
            if target is None:
                return (INVALID_ARGUMENT, 0)
        if type(source) is not str:
            source = _as_str(source)
            if source is None:
                return (INVALID_ARGUMENT, 1)
        # The memo slot of (target, source, t), by the ids' identity: an equal id in
        # another string object only misses. A hit is the very query: same objects (the
        # result holds them), same time, no insert or clear since.
        slot = (((<size_t><PyObject*>target) >> 4) ^ ((<size_t><PyObject*>source) >> 3)
                ^ <size_t>t ^ (<size_t>t >> 20)) & (MEMO_SIZE - 1)
        if self._memo_gen[slot] == self._generation and self._memo_t[slot] == t:
            hit = self._memo[slot]
            if (<tuple>hit)[1] is source and (<tuple>(<tuple>hit)[0])[1] is target:
                return hit
        if target == source:
            if t == 0:
                # tf2 stamps the identity with the frame's newest sample; an unknown id
                # maps to frame 0 (NO_PARENT), whose link exists only if "NO_PARENT" was
                # stored as a child (lookupFrameNumber / getFrame).
                cache = self._caches[self._frame_ids.get(target, 0)]
                if cache is not None:
                    (<Link>cache).c_latest(&t)
            _identity(v)
            return _stamped(_time_of(t) if t != (<object>time)._ns else time, target, source, v)
        target_id = self._frame(target)
        if target_id < 0:
            return _bad_id(<str>target, 0)
        source_id = self._frame(source)
        if source_id < 0:
            return _bad_id(<str>source, 1)
        used = t
        err = self._walk(target_id, source_id, &used, v, &where)
        if err != NO_ERROR:
            if err != EXTRAPOLATION_ERROR:
                return (err, 0)
            expired = False
            link = <Link>self._caches[where]
            gcode = link.c_gather(used, st, &p)
            if gcode != G_FUTURE and self._common(target_id, source_id, &lct) == NO_ERROR:
                expired = lct != 0 and used < lct - self._cache_ns
            return (err, where, used, expired)
        out = _restamp(self._memo, slot, time if used == t and t != 0 else _time_of(used),
                       target, source, v)
        self._memo[slot] = out
        self._memo_t[slot] = t
        self._memo_gen[slot] = self._generation
        return out

    def _chain(self, target_frame, source_frame, time=None):
        """The frames an answer for ``lookup_transform(target_frame, source_frame, time)``
        depends on, now and as data arrives: both ids, and the ancestors of each by its
        link's newest parent and, for a time other than 0, by its parent at ``time`` (a
        link re-parented over time), at most ``MAX_GRAPH_DEPTH + 1`` per chain (a longer
        walk is tf2's loop error). Unknown ids are included as given (they may arrive).
        Like tf2's ``_chainAsVector``, but as a set and for both parentage rules.

        Returns:
            A list of frame ids (no duplicates, in discovery order).
        """
        cdef int64_t t = 0 if time is None else (<object>time)._ns
        cdef list names = self._frame_names
        cdef list caches = self._caches
        cdef set seen = set()
        cdef list out = []
        cdef list todo = [target_frame, source_frame]
        cdef object name, fid, obj
        cdef int frame, parent, depth, p2
        cdef int64_t stamp
        cdef double st[7]
        while todo:
            name = todo.pop()
            if name in seen:
                continue
            seen.add(name)
            out.append(name)
            fid = self._frame_ids.get(name)
            if fid is None:
                continue
            frame = <int>fid
            depth = 0
            while frame != 0 and depth <= C_MAX_DEPTH:
                obj = _link(caches, frame)
                if obj is None:
                    break
                if t != 0:
                    p2 = 0
                    if (<Link>obj).c_gather(t, st, &p2) == G_OK and p2 != 0:
                        if names[p2] not in seen:
                            todo.append(names[p2])
                parent = (<Link>obj).c_latest(&stamp)
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

    cdef int _common(self, int target, int source, int64_t* out) except -1:
        """tf2 ``getLatestCommonTime``; NO_ERROR with ``out`` set, or an error code."""
        cdef list caches = self._caches
        cdef object obj
        cdef int64_t lct_stamp[C_MAX_DEPTH + 2]
        cdef int lct_parent[C_MAX_DEPTH + 2]
        cdef Py_ssize_t n = 0, k
        cdef int frame, parent, depth, common_parent
        cdef int64_t stamp, common
        cdef bint have = False, found
        out[0] = 0
        if source == target:
            obj = _link(caches, source)
            if obj is not None:
                (<Link>obj).c_latest(out)
            return NO_ERROR
        # Walk up from the source, remembering (stamp, parent) of each link.
        frame = source
        common = INT64_MAX
        depth = 0
        while frame != 0:
            obj = _link(caches, frame)
            if obj is None:
                break
            parent = (<Link>obj).c_latest(&stamp)
            if parent == 0:
                break
            if stamp and (not have or stamp < common):
                common = stamp
                have = True
            lct_stamp[n] = stamp
            lct_parent[n] = parent
            n += 1
            frame = parent
            if frame == target:
                out[0] = common if have else 0
                return NO_ERROR
            depth += 1
            if depth > C_MAX_DEPTH:
                return LOOKUP_ERROR
        # Walk up from the target until a parent seen on the source side.
        frame = target
        depth = 0
        have = False
        common = INT64_MAX
        common_parent = 0
        while True:
            obj = _link(caches, frame)
            if obj is None:
                break
            parent = (<Link>obj).c_latest(&stamp)
            if parent == 0:
                break
            if stamp and (not have or stamp < common):
                common = stamp
                have = True
            found = False
            for k in range(n):
                if lct_parent[k] == parent:
                    found = True
                    break
            if found:
                common_parent = parent
                break
            frame = parent
            if frame == source:
                out[0] = common if have else 0
                return NO_ERROR
            depth += 1
            if depth > C_MAX_DEPTH:
                return LOOKUP_ERROR
        if common_parent == 0:
            return CONNECTIVITY_ERROR
        for k in range(n):
            stamp = lct_stamp[k]
            if stamp and (not have or stamp < common):
                common = stamp
                have = True
            if lct_parent[k] == common_parent:
                break
        out[0] = common if have else 0
        return NO_ERROR

    def _ccommon_time(self, int target_id, int source_id):
        """``(NO_ERROR, time ns)``, or ``(LOOKUP_ERROR (loop) | CONNECTIVITY_ERROR, 0)``."""
        cdef int64_t t = 0
        cdef int err = self._common(target_id, source_id, &t)
        return err, t

    # ------------------------------------------------------------------ public state

    def clear(self):
        """Drop every stored sample, keeping the frames and their links (tf2
        ``BufferCore::clear``). As in tf2, the reserved frame 0 (``NO_PARENT``) is
        skipped: a link stored with child ``"NO_PARENT"`` keeps its samples."""
        cdef object cache
        cdef Py_ssize_t fid
        self._generation += 1
        for cache in self._caches[1:]:
            if cache is not None:
                cache.clear()
        # Every dynamic link's newest stamp is 0 now: ``forget`` finds them first; the
        # newest stamp stored starts over (a clock that jumped back: older stamps follow).
        self._newest = 0
        if self._expiring:
            self._expire_due = self._expire_every
        self._heap = [
            (0, fid) for fid in range(1, len(self._caches))
            if isinstance(self._caches[fid], TimeCache)
        ]

    def get_frame_names(self):
        """Every known frame id (children and parents), in the order of their numbers
        (registration order; a frame registered after ``forget`` may take the number of
        a forgotten one)."""
        if self._free:
            return [name for name in self._frame_names[1:] if name]
        return self._frame_names[1:]

    def frame_exists(self, frame_id):
        """Whether ``frame_id`` is known (tf2 ``_frameExists``)."""
        return self._frame_ids.get(frame_id, 0) != 0

    def parent_of(self, frame_id, int64_t time_ns):
        """The parent id of ``frame_id`` at ``time_ns`` (0 = latest), or None for a root,
        an unknown frame or a time its link has no data for (tf2 ``_getParent``)."""
        cdef object fid = self._frame_ids.get(frame_id, 0)
        cdef object cache = self._caches[fid] if fid else None
        if cache is None:
            return None
        r = cache.gather(time_ns)
        if isinstance(r, str) or r[0] == 0:
            return None
        return self._frame_names[r[0]]

    def link_info(self):
        """Per linked frame, in registration order, ``(child, parent, authority,
        is_static, samples, oldest_ns, newest_ns)``; the parent of an emptied link is
        ``NO_PARENT``, a link with no recorded authority says so."""
        cdef list names = self._frame_names
        cdef list out = []
        cdef Py_ssize_t fid
        cdef object cache, r
        for fid in range(1, len(self._caches)):
            cache = self._caches[fid]
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
            ))
        return out

    def extrapolation_detail(self, int where, int64_t used):
        """tf2's extrapolation text of the link of frame ``where`` (the int id a failed
        query reported) at ``used`` ns: ``"Lookup would require extrapolation ..."``;
        ``""`` for no link or a link that can answer that time."""
        cache = self._caches[where] if 0 < where < len(self._caches) else None
        detail = cache.gather(used) if cache is not None else ""
        return detail if isinstance(detail, str) else ""

    def common_time(self, target_frame, source_frame):
        """tf2 ``getLatestCommonTime`` for two known frame ids: ``(NO_ERROR, time ns)``,
        or ``(LOOKUP_ERROR (a loop) | CONNECTIVITY_ERROR, 0)``.

        Raises:
            KeyError: an id is unknown (validate first).
        """
        return self._ccommon_time(self._frame_ids[target_frame], self._frame_ids[source_frame])

    cdef int _walk(self, int target_id, int source_id, int64_t* time, double* out,
                   int* where) except -1:
        """tf2 ``walkToTopParent`` with ``TransformAccum``: ``out`` = the transform mapping
        source coordinates into target coordinates at ``time[0]`` (0 = latest common time,
        replaced by the time used). Returns NO_ERROR, LOOKUP_ERROR (a loop),
        CONNECTIVITY_ERROR, or EXTRAPOLATION_ERROR with ``where`` = the frame whose link had
        no data."""
        cdef list caches = self._caches
        cdef double src[7]
        cdef double tgt[7]
        cdef double r[3]
        cdef double q[4]
        cdef int top = 0, frame = 0, src_failed_at = 0
        cdef int outcome, err
        cdef bint failed
        if source_id == target_id:
            _identity(out)
            return NO_ERROR
        if time[0] == 0:
            err = self._common(target_id, source_id, time)
            if err:
                return err

        # Source side: source -> top. A failure here is only remembered: the path may
        # still close below it (only links between the two frames must be valid).
        outcome = _climb(caches, source_id, 0, target_id, time[0], src, &top)
        if outcome == CLIMB_EARLY:  # TargetParentOfSource
            memcpy(out, src, 7 * sizeof(double))
            return NO_ERROR
        if outcome == CLIMB_LOOP:
            return LOOKUP_ERROR
        failed = outcome == CLIMB_FAILED
        if failed:
            src_failed_at = top

        # Target side: target -> top. A failure here is reported at once.
        outcome = _climb(caches, target_id, top, source_id, time[0], tgt, &frame)
        if outcome == CLIMB_FAILED:
            where[0] = frame
            return EXTRAPOLATION_ERROR
        if outcome == CLIMB_LOOP:
            return LOOKUP_ERROR
        if outcome == CLIMB_EARLY:  # SourceParentOfTarget: the source side is unused
            _identity(src)
        elif frame != top:
            if failed:
                where[0] = src_failed_at
                return EXTRAPOLATION_ERROR
            return CONNECTIVITY_ERROR

        # FullPath: inv(target -> top) ∘ (source -> top), inv = (conj q, conj q * (-t)):
        # conj(q) applied to (s - g), then conj(q) ⊗ q_s.
        _qrot(-tgt[3], -tgt[4], -tgt[5], tgt[6], src[0] - tgt[0], src[1] - tgt[1],
              src[2] - tgt[2], r)
        _qmul(-tgt[3], -tgt[4], -tgt[5], tgt[6], src[3], src[4], src[5], src[6], q)
        out[0] = r[0]
        out[1] = r[1]
        out[2] = r[2]
        out[3] = q[0]
        out[4] = q[1]
        out[5] = q[2]
        out[6] = q[3]
        return NO_ERROR

    cdef int _walk_policy(self, int target_id, int source_id, int64_t* time, int mode,
                          int64_t before, int64_t after, double* out, int* where,
                          int* sf, int64_t* ss, Py_ssize_t* n) except -1:
        """``_walk`` with each link's sample picked by a lookup policy; on success ``sf``
        / ``ss`` (room for ``2 * C_MAX_DEPTH + 4``) hold the child frame and sample stamp
        of each of the ``n`` links on the path (source side upwards, then target side
        downwards; links above the common ancestor, gathered by both sides, are left
        out)."""
        cdef list caches = self._caches
        cdef double src[7]
        cdef double tgt[7]
        cdef double r[3]
        cdef double q[4]
        cdef int top = 0, frame = 0, src_failed_at = 0
        cdef int outcome, err
        cdef Py_ssize_t m = 0, k
        cdef bint failed
        cdef int* tf = &sf[C_MAX_DEPTH + 2]
        cdef int64_t* ts = &ss[C_MAX_DEPTH + 2]
        n[0] = 0
        if source_id == target_id:
            _identity(out)
            return NO_ERROR
        if time[0] == 0:
            err = self._common(target_id, source_id, time)
            if err:
                return err
        outcome = _climb_policy(caches, source_id, 0, target_id, time[0], mode, before,
                                after, src, &top, sf, ss, n)
        if outcome == CLIMB_EARLY:
            memcpy(out, src, 7 * sizeof(double))
            return NO_ERROR
        if outcome == CLIMB_LOOP:
            return LOOKUP_ERROR
        failed = outcome == CLIMB_FAILED
        if failed:
            src_failed_at = top
        outcome = _climb_policy(caches, target_id, top, source_id, time[0], mode, before,
                                after, tgt, &frame, tf, ts, &m)
        if outcome == CLIMB_FAILED:
            where[0] = frame
            return EXTRAPOLATION_ERROR
        if outcome == CLIMB_LOOP:
            return LOOKUP_ERROR
        if outcome == CLIMB_EARLY:
            _identity(src)
            n[0] = 0
        elif frame != top:
            if failed:
                where[0] = src_failed_at
                return EXTRAPOLATION_ERROR
            return CONNECTIVITY_ERROR
        # The links above the common ancestor were gathered by both sides: drop them.
        while n[0] and m and sf[n[0] - 1] == tf[m - 1]:
            n[0] -= 1
            m -= 1
        while m:
            m -= 1
            sf[n[0]] = tf[m]
            ss[n[0]] = ts[m]
            n[0] += 1
        _qrot(-tgt[3], -tgt[4], -tgt[5], tgt[6], src[0] - tgt[0], src[1] - tgt[1],
              src[2] - tgt[2], r)
        _qmul(-tgt[3], -tgt[4], -tgt[5], tgt[6], src[3], src[4], src[5], src[6], q)
        out[0] = r[0]
        out[1] = r[1]
        out[2] = r[2]
        out[3] = q[0]
        out[4] = q[1]
        out[5] = q[2]
        out[6] = q[3]
        return NO_ERROR

    def _query_policy(self, object target, object source, time, tuple policy):
        """``_query`` under a lookup policy (:mod:`tfbus.core.policy`; ``policy`` its
        ``(mode, before ns, after ns)``, mode 1 nearest, 2 clamp, 3 previous): the
        :class:`~tfbus.core.policy.PolicyResult` (transform and report, not memoised), or
        ``_query``'s failure tuple (the failing link's tf2 failure at the time)."""
        cdef int64_t t = (<object>time)._ns
        cdef int mode = policy[0]
        cdef int64_t before = policy[1], after = policy[2]
        cdef int64_t used, lct, s, d, worst = 0
        cdef int target_id, source_id, err, where = 0, gcode = 0
        cdef double v[7]
        cdef double st[7]
        cdef int p = 0
        cdef bint expired
        cdef Link link
        cdef list names
        cdef object out, o
        cdef Py_ssize_t k, n = 0
        cdef tuple frames, stamps
        cdef int fr[2 * C_MAX_DEPTH + 4]
        cdef int64_t ss[2 * C_MAX_DEPTH + 4]
        if type(target) is not str:
            target = _as_str(target)
            if target is None:
                return (INVALID_ARGUMENT, 0)
        if type(source) is not str:
            source = _as_str(source)
            if source is None:
                return (INVALID_ARGUMENT, 1)
        if target == source:
            out = self._query(target, source, time)
            return _named(PolicyResult, out, _named3(PolicyReport, (), (), 0))
        target_id = self._frame(target)
        if target_id < 0:
            return _bad_id(<str>target, 0)
        source_id = self._frame(source)
        if source_id < 0:
            return _bad_id(<str>source, 1)
        used = t
        err = self._walk_policy(target_id, source_id, &used, mode, before, after, v, &where,
                                fr, ss, &n)
        if err != NO_ERROR:
            if err != EXTRAPOLATION_ERROR:
                return (err, 0)
            expired = False
            link = <Link>self._caches[where]
            gcode = link.c_gather(used, st, &p)
            if gcode != G_FUTURE and self._common(target_id, source_id, &lct) == NO_ERROR:
                expired = lct != 0 and used < lct - self._cache_ns
            return (err, where, used, expired)
        names = self._frame_names
        frames = PyTuple_New(n)
        stamps = PyTuple_New(n)
        for k in range(n):
            o = names[fr[k]]
            Py_INCREF(o)
            PyTuple_SET_ITEM(frames, k, o)
            s = ss[k]
            o = s
            Py_INCREF(o)
            PyTuple_SET_ITEM(stamps, k, o)
            d = s - used if s >= used else used - s
            if d > worst:
                worst = d
        out = _stamped(time if used == t and t != 0 else _time_of(used), target, source, v)
        return _named(PolicyResult, out, _named3(PolicyReport, frames, stamps, worst))

    def _cwalk(self, int target_id, int source_id, int64_t time):
        """tf2 ``walkToTopParent`` with ``TransformAccum`` (see ``_walk``).

        Returns ``(NO_ERROR, 7-tuple, time used)``, ``(EXTRAPOLATION_ERROR, id of the
        frame whose link had no data, time)``, ``(CONNECTIVITY_ERROR, None, 0)`` or
        ``(LOOKUP_ERROR, None, 0)`` (a loop).
        """
        cdef double v[7]
        cdef int where = 0
        cdef int err = self._walk(target_id, source_id, &time, v, &where)
        if err == NO_ERROR:
            return NO_ERROR, (v[0], v[1], v[2], v[3], v[4], v[5], v[6]), time
        if err == EXTRAPOLATION_ERROR:
            return err, where, time
        return err, None, 0

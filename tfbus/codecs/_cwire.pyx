# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, embedsignature=True
"""Wire decoders and writers, compiled: ``_tf_from_ros1`` turns a ROS 1 serialised
``TFMessage`` into TransformStamped values, built in C like the lookups' results (the fast path of
:func:`tfbus.codecs.ros1.decode_tf`; the pure-Python twin is
:func:`tfbus.codecs.ros1.decode_ros1_struct`), and ``_tf_from_native`` does the same for a
TFMessage payload of tfbus's own wire in the form tfbus writes it (the fast path of
:meth:`tfbus.codecs.native.WireCodec.decode`; msgspec's schema decodes everything else);
``_clock_stamp_native`` reads the stamp of a ``Clock`` payload of that wire (the fast path
of :func:`tfbus.transports.zenoh.transport.clock_stamp`), ``_clock_from_cdr`` a ROS 2
``Clock`` sample (the fast path of :func:`tfbus.codecs.cdr.decode_clock`), ``_tf_to_ros1``
writes a ROS 1 ``TFMessage`` of the common form (the fast path of :func:`tfbus.codecs.ros1._encode_struct`
and ``TFCodec.encode_framed``), and ``_tf_to_native`` writes a TFMessage payload of tfbus's
own wire of that form, the bytes msgspec writes (the fast path of
:meth:`tfbus.codecs.native.WireCodec.encode`).
They use the compiled core's C helpers (``tfbus/core/_ccore.pxd``, ``_cresults.pxd``), so
they are built with the compiled core and loaded only with it (:mod:`tfbus.codecs.ros1`
and :mod:`tfbus.codecs.native` choose)."""

from cpython.bytes cimport PyBytes_AS_STRING, PyBytes_GET_SIZE
from cpython.float cimport PyFloat_FromDouble
from cpython.object cimport PyObject
from cpython.ref cimport Py_DECREF, Py_INCREF
from libc.string cimport memcpy, memset
from cpython.unicode cimport PyUnicode_GET_LENGTH
from libc.stdint cimport int64_t

from tfbus.core._ccore cimport _plain_values, _time_of
from tfbus.core._cresults cimport PyObject_GC_UnTrack, _named, _named1, _named3, _named4
from tfbus.messages import (Clock, Header, Quaternion, TFMessage, Transform, TransformStamped,
                            Vector3)
from tfbus.time import Time

from struct import error as _StructError

from cpython.list cimport PyList_AsTuple, PyList_New, PyList_SET_ITEM
from cpython.unicode cimport PyUnicode_DecodeUTF8
from libc.stdint cimport uint32_t, uint64_t
from libc.string cimport memcmp


cdef extern from "Python.h":
    int PyUnicode_IS_ASCII(object o)
    void* PyUnicode_DATA(object o)


# Frame ids by their position in a message: a publisher sends the same ids message
# after message, so an id whose bytes equal the ASCII str decoded last time at the same
# position is that (immutable) str again, not a new one. Compared byte for byte on
# every use; a different id replaces it. Positions past _ROS1_ID_SLOTS are decoded. Only
# ids of at most _ROS1_ID_MAX bytes are kept (as the pure-Python twin's
# _STR_CACHE_KEY_MAX): what the cache holds stays under 4096 * 256 bytes per list,
# whatever ids a publisher sends (a long id at every position, kept by non-ASCII ids at
# the positions before it, would otherwise hold up to 4096 messages' worth of ids).
DEF _ROS1_ID_SLOTS = 4096
DEF _ROS1_ID_MAX = 256
cdef list _ros1_children = [None] * _ROS1_ID_SLOTS
cdef list _ros1_frames = [None] * _ROS1_ID_SLOTS


cdef inline object _ros1_id(list cache, Py_ssize_t k, const unsigned char* s, uint32_t n):
    """The str of the UTF-8 bytes ``s[:n]``: the one cached at ``k`` if equal."""
    cdef object cached
    if k < _ROS1_ID_SLOTS:
        cached = cache[k]
        if (cached is not None and <uint32_t>PyUnicode_GET_LENGTH(cached) == n
                and memcmp(PyUnicode_DATA(cached), s, n) == 0):
            return cached
    cdef object text = PyUnicode_DecodeUTF8(<const char*>s, n, NULL)
    if k < _ROS1_ID_SLOTS and n <= _ROS1_ID_MAX and PyUnicode_IS_ASCII(text):
        cache[k] = text
    return text


# Transform values by their position in a message, alike: a publisher sends many of the
# same values message after message (robot_state_publisher's joint origins, identity
# rotations, a robot standing still), so a Transform, Vector3 or Quaternion whose 56, 24
# or 32 bytes equal those decoded last time at the same position is that (immutable)
# value again, not new floats and tuples. Compared byte for byte (so 0.0 and -0.0, or two
# NaN payloads, are told apart) on every use; different bytes replace it.
#
# Values that change (a robot moving every joint) cannot be shared; but the objects of a
# message nobody holds any more can be used again, as CPython's ``zip`` reuses its result
# tuple when only it holds it (``zip_next``, Objects/bltinmodule.c). Each position keeps
# the TransformStamped it gave two decodes ago (the last one is usually still held: an
# ``async for`` loop keeps its message until the next arrives); when that object, its
# Transform, Vector3, Quaternion or floats are referenced by nothing but their holder
# here, nobody can see them any more, and they are filled with the new values in place
# instead of being freed by the user and allocated here again (about 11 objects a
# transform). Anything a user still holds (the message, a transform, a rotation, a float)
# has other references, is never changed, and a new object is made in its place.
# CPython 3.14 caches tuple hashes and free-threaded builds cannot trust a reference
# count of 1: there, nothing is reused.
cdef extern from *:
    """
    #if PY_VERSION_HEX >= 0x030E0000 || defined(Py_GIL_DISABLED)
    #define TFBUS_REUSE 0
    #else
    #define TFBUS_REUSE 1
    #endif
    """
    const bint TFBUS_REUSE


cdef extern from "Python.h":
    ctypedef struct PyFloatObject:
        double ob_fval
    Py_ssize_t _refcnt "Py_REFCNT"(PyObject* o)
    PyObject* _item "PyTuple_GET_ITEM"(PyObject* t, Py_ssize_t i)
    PyObject* _list_item "PyList_GET_ITEM"(PyObject* t, Py_ssize_t i)
    void _set_item "PyTuple_SET_ITEM"(PyObject* t, Py_ssize_t i, PyObject* o)
    bint _is_float "PyFloat_CheckExact"(PyObject* o)
    void _incref "Py_INCREF"(PyObject* o)
    void _decref "Py_DECREF"(PyObject* o)


_REUSES = bool(TFBUS_REUSE)
"""Whether this build refills the objects nobody holds any more (False on CPython 3.14+
and free-threaded builds)."""


cdef class _Positions:
    """What the decodes of one wire left at each position of a message (the first
    ``_ROS1_ID_SLOTS``): the last Transform and its 7 doubles, and the TransformStampeds
    of the last two decodes (``turn`` says which of the two a position gives next)."""

    cdef list transforms
    cdef list spares
    cdef double values[_ROS1_ID_SLOTS * 7]
    cdef unsigned char turn[_ROS1_ID_SLOTS]

    def __cinit__(self):
        self.transforms = [None] * _ROS1_ID_SLOTS
        self.spares = [None] * (2 * _ROS1_ID_SLOTS)
        memset(self.turn, 0, _ROS1_ID_SLOTS)


# One per wire: a process may follow both, with different values at the same positions.
cdef _Positions _ros1_at = _Positions()
cdef _Positions _native_at = _Positions()


cdef inline PyObject* _sole_item(PyObject* t, Py_ssize_t i) noexcept:
    """Item ``i`` of tuple ``t`` (which only this module references) when ``t`` is its
    only holder, else NULL."""
    cdef PyObject* o
    if t == NULL:
        return NULL
    o = _item(t, i)
    return o if _refcnt(o) == 1 else NULL


cdef inline void _replace(PyObject* t, Py_ssize_t i, object new) noexcept:
    """Item ``i`` of tuple ``t`` (only this module references it) becomes ``new``."""
    cdef PyObject* old = _item(t, i)
    if old == <PyObject*>new:
        return
    _incref(<PyObject*>new)
    _set_item(t, i, <PyObject*>new)
    _decref(old)


cdef inline void _fill(PyObject* t, const double* v, Py_ssize_t n):
    """The floats of tuple ``t`` (only this module references it) become ``v[:n]``: a
    float only ``t`` holds is changed in place, any other replaced by a new one."""
    cdef PyObject* f
    cdef Py_ssize_t i
    for i in range(n):
        f = _item(t, i)
        if _refcnt(f) == 1 and _is_float(f):
            (<PyFloatObject*>f).ob_fval = v[i]
        else:
            _replace(t, i, PyFloat_FromDouble(v[i]))


cdef inline object _transform(_Positions at, Py_ssize_t k, const double* v,
                              PyObject* spare):
    """The Transform of the 7 doubles ``v`` (translation x y z, rotation x y z w): the
    one ``at`` position ``k`` holds, or one sharing its Vector3 or Quaternion, when the
    bytes match; else ``spare`` (a Transform only this module references, or NULL)
    refilled, or a new one."""
    cdef object cached = None, vec = None, rot = None, tf
    cdef double* old
    cdef PyObject* part
    if k < _ROS1_ID_SLOTS:
        cached = at.transforms[k]
        if cached is not None:
            old = at.values + 7 * k
            if memcmp(old, v, 7 * sizeof(double)) == 0:
                return cached
            if memcmp(old, v, 3 * sizeof(double)) == 0:
                vec = (<tuple>cached)[0]
            elif memcmp(old + 3, v + 3, 4 * sizeof(double)) == 0:
                rot = (<tuple>cached)[1]
    if vec is None:
        part = _sole_item(spare, 0)
        if part != NULL:
            _fill(part, v, 3)
            vec = <object>part
        else:
            vec = _named3(Vector3, PyFloat_FromDouble(v[0]), PyFloat_FromDouble(v[1]),
                          PyFloat_FromDouble(v[2]))
            PyObject_GC_UnTrack(<PyObject*>vec)  # three floats: never part of a cycle
    if rot is None:
        part = _sole_item(spare, 1)
        if part != NULL:
            _fill(part, v + 3, 4)
            rot = <object>part
        else:
            rot = _named4(Quaternion, v[3], v[4], v[5], v[6])
    if spare != NULL:
        _replace(spare, 0, vec)
        _replace(spare, 1, rot)
        tf = <object>spare
    else:
        tf = _named(Transform, vec, rot)
        PyObject_GC_UnTrack(<PyObject*>tf)  # two untracked tuples: never part of a cycle
    if k < _ROS1_ID_SLOTS:
        at.transforms[k] = tf
        memcpy(at.values + 7 * k, v, 7 * sizeof(double))
    return tf


cdef inline object _stamped(_Positions at, Py_ssize_t k, object header, object child,
                            const double* v):
    """The TransformStamped at position ``k`` of a message: ``header``, ``child`` and the
    Transform of the 7 doubles ``v`` (:func:`_transform`), in the object this position
    gave two decodes ago when nothing else references it any more (refilled), else a
    new one; kept for the decode after next."""
    cdef Py_ssize_t slot
    cdef PyObject* held
    cdef object ts
    if not TFBUS_REUSE or k >= _ROS1_ID_SLOTS:
        return _named3(TransformStamped, header, child, _transform(at, k, v, NULL))
    # Take this position's TransformStamped of two decodes ago out of its slot: held by
    # ``ts`` alone when nobody else holds it (then it, and whatever of it only it holds,
    # is refilled; nothing else can reach it meanwhile).
    slot = 2 * k + at.turn[k]
    at.turn[k] ^= 1
    held = _list_item(<PyObject*>at.spares, slot)
    if held != <PyObject*>None and _refcnt(held) == 1:
        ts = <object>held
        at.spares[slot] = None
        _replace(held, 2, _transform(at, k, v, _sole_item(held, 2)))
        _replace(held, 0, header)
        _replace(held, 1, child)
    else:
        ts = _named3(TransformStamped, header, child, _transform(at, k, v, NULL))
    at.spares[slot] = ts
    return ts


cdef inline uint32_t _u32le(const unsigned char* p) noexcept:
    return <uint32_t>p[0] | (<uint32_t>p[1] << 8) | (<uint32_t>p[2] << 16) | (<uint32_t>p[3] << 24)


cdef enum:
    _ROS1_TF_MIN = 76  # bytes of a transform with empty ids: 4 u32 + 2 u32 + 7 float64


def _tf_from_ros1(const unsigned char[::1] buf):
    """The transforms of a ROS 1 serialised ``tf2_msgs/TFMessage`` (``u32 count``, then
    per transform ``u32 seq, u32 sec, u32 nsec, u32 len, frame_id, u32 len,
    child_frame_id, 7 float64``, little endian), built in C: what
    ``tfbus.codecs.ros1.decode_ros1_struct`` returns, equal values (frame ids
    decoded as strict UTF-8; a transform whose serialised header is byte for byte the
    previous one's shares its Header; an ASCII frame id equal to the one at the same
    position of an earlier message is that message's str, not a new one, and a transform
    whose 7 doubles (or translation, or rotation) are byte for byte those at the same
    position of the last message is that message's Transform (Vector3, Quaternion);
    the objects of the transform decoded two messages earlier at the same position
    that nothing else references any more are refilled rather than made anew, see
    ``_REUSES``; bytes after the last transform are ignored).
    Little-endian hosts only (the doubles are read in host order).

    Raises:
        struct.error: the payload is shorter than its contents.
        UnicodeDecodeError: a frame id is not UTF-8.
    """
    cdef Py_ssize_t size = buf.shape[0], off = 4, head, hlen = 0, prev = -1, k
    cdef const unsigned char* p
    cdef uint32_t n, flen, clen, sec, nsec
    cdef double v[7]
    cdef object header = None, child
    cdef list out
    if size < 4:
        raise _StructError("message shorter than its contents")
    p = &buf[0]
    n = _u32le(p)
    if n > (size - 4) // _ROS1_TF_MIN:
        raise _StructError("message shorter than its contents")
    out = PyList_New(n)
    for k in range(n):
        # The list owns a reference to None in each slot until it is set (PyList_New
        # leaves NULLs, which a failure below must not expose).
        Py_INCREF(None)
        PyList_SET_ITEM(out, k, None)
    for k in range(n):
        head = off
        if off + 16 > size:
            raise _StructError("message shorter than its contents")
        flen = _u32le(p + off + 12)
        if flen > size - off - 16:
            raise _StructError("message shorter than its contents")
        off += 16 + flen
        if not (prev >= 0 and hlen == off - head and memcmp(p + prev, p + head, hlen) == 0):
            sec = _u32le(p + head + 4)
            nsec = _u32le(p + head + 8)
            header = _named(
                Header,
                _time_of(<int64_t>sec * 1000000000 + nsec),
                _ros1_id(_ros1_frames, k, p + head + 16, flen),
            )
            prev = head
            hlen = off - head
        if off + 4 > size:
            raise _StructError("message shorter than its contents")
        clen = _u32le(p + off)
        if clen > size - off - 4 or size - off - 4 - clen < 56:
            raise _StructError("message shorter than its contents")
        child = _ros1_id(_ros1_children, k, p + off + 4, clen)
        off += 4 + clen
        memcpy(v, p + off, 7 * sizeof(double))
        off += 56
        out[k] = _stamped(_ros1_at, k, header, child, v)
    return out


# -- tfbus's own wire (msgpack, tfbus.codecs.native) ---------------------------------------
# Frame ids by position, as for ROS 1 above, in lists of their own (a process may follow
# both wires).
cdef list _native_children = [None] * _ROS1_ID_SLOTS
cdef list _native_frames = [None] * _ROS1_ID_SLOTS


cdef inline uint64_t _be(const unsigned char* p, int n) noexcept:
    """The big-endian unsigned integer of the ``n`` bytes at ``p`` (msgpack's order)."""
    cdef uint64_t v = 0
    cdef int i
    for i in range(n):
        v = (v << 8) | p[i]
    return v


cdef inline Py_ssize_t _array(const unsigned char* p, Py_ssize_t size, Py_ssize_t* off) noexcept:
    """The length of the msgpack array at ``p[off]`` (fixarray, array 16, array 32), its
    header skipped; -1 when it is not an array or is cut short."""
    cdef Py_ssize_t o = off[0]
    cdef unsigned char b
    if o >= size:
        return -1
    b = p[o]
    if 0x90 <= b <= 0x9f:
        off[0] = o + 1
        return b & 0x0f
    if b == 0xdc and o + 3 <= size:
        off[0] = o + 3
        return <Py_ssize_t>_be(p + o + 1, 2)
    if b == 0xdd and o + 5 <= size:
        off[0] = o + 5
        return <Py_ssize_t>_be(p + o + 1, 4)
    return -1


cdef inline int _uint63(const unsigned char* p, Py_ssize_t size, Py_ssize_t* off,
                        int64_t* out) noexcept:
    """The msgpack integer at ``p[off]`` when it is in [0, 2**63): 1 and ``out`` set, its
    bytes skipped; 0 for anything else (another type, a negative value, cut short)."""
    cdef Py_ssize_t o = off[0]
    cdef unsigned char b
    cdef int n
    cdef uint64_t v
    if o >= size:
        return 0
    b = p[o]
    if b <= 0x7f:
        out[0] = b
        off[0] = o + 1
        return 1
    if 0xcc <= b <= 0xcf:  # uint 8, 16, 32, 64
        n = 1 << (b - 0xcc)
    elif 0xd0 <= b <= 0xd3:  # int 8, 16, 32, 64: a non-negative value only
        n = 1 << (b - 0xd0)
        if o + 1 < size and p[o + 1] & 0x80:
            return 0
    else:
        return 0
    if o + 1 + n > size:
        return 0
    v = _be(p + o + 1, n)
    if v > <uint64_t>0x7fffffffffffffff:
        return 0
    out[0] = <int64_t>v
    off[0] = o + 1 + n
    return 1


cdef inline object _native_id(list cache, Py_ssize_t k, const unsigned char* p,
                              Py_ssize_t size, Py_ssize_t* off, Py_ssize_t max_length):
    """The msgpack str at ``p[off]`` (fixstr, str 8, 16, 32), its bytes skipped: the one
    cached at ``k`` when equal (see ``_ros1_id``); None when it is not a str, is cut short,
    is not UTF-8 or is longer than ``max_length`` characters."""
    cdef Py_ssize_t o = off[0], n
    cdef unsigned char b
    cdef int width
    cdef object text
    if o >= size:
        return None
    b = p[o]
    if 0xa0 <= b <= 0xbf:
        n = b & 0x1f
        o += 1
    elif 0xd9 <= b <= 0xdb:
        width = 1 << (b - 0xd9)  # bytes of the length: 1, 2, 4
        if o + 1 + width > size:
            return None
        n = <Py_ssize_t>_be(p + o + 1, width)
        o += 1 + width
    else:
        return None
    if n > size - o:
        return None
    off[0] = o + n
    try:
        text = _ros1_id(cache, k, p + o, <uint32_t>n)
    except UnicodeDecodeError:
        return None
    if PyUnicode_GET_LENGTH(text) > max_length:
        return None
    return text


cdef inline int _float64s(const unsigned char* p, Py_ssize_t size, Py_ssize_t* off,
                          double* out, Py_ssize_t n) noexcept:
    """An array of exactly ``n`` msgpack float 64s at ``p[off]`` into ``out``: 1, its bytes
    skipped; 0 for anything else."""
    cdef Py_ssize_t i
    cdef uint64_t bits
    if _array(p, size, off) != n:
        return 0
    for i in range(n):
        if off[0] + 9 > size or p[off[0]] != 0xcb:
            return 0
        bits = _be(p + off[0] + 1, 8)
        memcpy(&out[i], &bits, 8)
        off[0] += 9
    return 1


def _tf_from_native(bytes payload not None, Py_ssize_t max_bytes, Py_ssize_t max_transforms,
                    Py_ssize_t max_id, int magic, int version):
    """A tfbus wire payload (``tfbus.codecs.native``: ``magic``, ``version``, then the
    msgpack array ``[sender, seq, "tf", body]``) of a TFMessage in the form tfbus writes
    it, decoded in C: ``(sender, seq, TFMessage)``, the values ``WireCodec``'s msgspec
    schema decodes from it (equal, tested; an ASCII frame id equal to the one at the same
    position of the last message is that message's str, a transform whose header
    bytes equal the previous transform's shares its Header, and its values and objects
    are shared and refilled by position as ``_tf_from_ros1``'s are, in positions of this
    wire's own). None for anything else,
    which the caller decodes by that schema (and which raises what is wrong with it):
    another tag, a sender or sequence number outside [1, 2**63), an array of another
    length, an integer or float 32 where a float 64 is, a stamp outside [0, 2**63) ns,
    an id that is not UTF-8 or longer than ``max_id`` characters, more than
    ``max_transforms`` transforms, bytes left over; and a payload of more than ``max_bytes``
    bytes, fewer than 2, or another magic byte or version, which the caller's checks then
    name."""
    cdef Py_ssize_t size = PyBytes_GET_SIZE(payload), off = 2, n, k, head, hlen = 0
    cdef Py_ssize_t prev = -1
    cdef const unsigned char* p = <const unsigned char*> PyBytes_AS_STRING(payload)
    cdef int64_t sender, seq, stamp, last_stamp = -1
    cdef double v[7]
    cdef object header = None, time = None, frame, child
    cdef list out
    if size < 2 or size > max_bytes or p[0] != magic or p[1] != version:
        return None
    if _array(p, size, &off) != 4:
        return None
    if not _uint63(p, size, &off, &sender) or not _uint63(p, size, &off, &seq):
        return None
    if sender == 0 or seq == 0:
        return None
    if off + 3 > size or p[off] != 0xa2 or p[off + 1] != 0x74 or p[off + 2] != 0x66:  # "tf"
        return None
    off += 3
    n = _array(p, size, &off)
    # Every transform takes more than 64 bytes: a count the payload cannot hold is not
    # allocated for.
    if n < 0 or n > max_transforms or n > (size - off) // 64:
        return None
    out = PyList_New(n)
    for k in range(n):  # as in _tf_from_ros1: no NULL slot if a transform is refused
        Py_INCREF(None)
        PyList_SET_ITEM(out, k, None)
    for k in range(n):
        if _array(p, size, &off) != 3:
            return None
        head = off
        if _array(p, size, &off) != 2 or not _uint63(p, size, &off, &stamp):
            return None
        frame = _native_id(_native_frames, k, p, size, &off, max_id)
        if frame is None:
            return None
        if not (prev >= 0 and hlen == off - head and memcmp(p + prev, p + head, hlen) == 0):
            if stamp != last_stamp:  # the transforms of a message often share a stamp
                time = _time_of(stamp)
                last_stamp = stamp
            header = _named(Header, time, frame)
            prev = head
            hlen = off - head
        child = _native_id(_native_children, k, p, size, &off, max_id)
        if child is None:
            return None
        if (_array(p, size, &off) != 2 or not _float64s(p, size, &off, v, 3)
                or not _float64s(p, size, &off, v + 3, 4)):
            return None
        out[k] = _stamped(_native_at, k, header, child, v)
    if off != size:
        return None
    return sender, seq, _named1(TFMessage, PyList_AsTuple(out))



def _clock_stamp_native(bytes payload, int magic, int version):
    """The stamp (int ns) of a tfbus wire payload (``magic``, ``version``, then the msgpack
    array ``[sender, seq, "Clock", [ns]]``) of a ``Clock`` in the form tfbus writes it,
    read in C: a sender and sequence number in [1, 2**63), the tag a fixstr, the body an
    array of one integer in [0, 2**63) ns, nothing left over. -1 for anything else
    (another form, or a value out of range), which the caller reads by msgspec
    (:func:`tfbus.transports.zenoh.transport.clock_stamp`, whose answer this one equals
    wherever it is not -1: tested)."""
    cdef const unsigned char* p = payload
    cdef Py_ssize_t size = len(payload), off = 2
    cdef int64_t sender, seq, ns
    if size < 2 or p[0] != magic or p[1] != version:
        return -1
    if _array(p, size, &off) != 4:
        return -1
    if not _uint63(p, size, &off, &sender) or not _uint63(p, size, &off, &seq):
        return -1
    if sender == 0 or seq == 0:
        return -1
    if off + 6 > size or p[off] != 0xa5 or memcmp(p + off + 1, b"Clock", 5) != 0:
        return -1
    off += 6
    if _array(p, size, &off) != 1 or not _uint63(p, size, &off, &ns) or off != size:
        return -1
    return ns


cdef inline uint32_t _u32be(const unsigned char* p) noexcept:
    return (<uint32_t>p[0] << 24) | (<uint32_t>p[1] << 16) | (<uint32_t>p[2] << 8) | p[3]


def _clock_from_cdr(object data):
    """The :class:`~tfbus.messages.Clock` of a serialized ``rosgraph_msgs/msg/Clock`` (the
    encapsulation header, then ``builtin_interfaces/Time``: int32 ``sec``, uint32
    ``nanosec``; XCDR1 or ``PLAIN_CDR2``, either byte order), built in C: what
    :func:`tfbus.codecs.cdr.decode_clock` returns for it (its stamp ``sec * 10**9 +
    nanosec`` ns). None for anything that function refuses or that is not ``bytes`` (the
    caller then asks it, for its answer or its ``WireDecodeError``: equal wherever this
    one answers, tested)."""
    if type(data) is not bytes:
        return None
    cdef const unsigned char* p = <const unsigned char*>PyBytes_AS_STRING(data)
    cdef Py_ssize_t size = PyBytes_GET_SIZE(data)
    cdef uint32_t sec, nanosec
    if size < 12 or p[0] != 0:
        return None
    if p[1] == 0x01 or p[1] == 0x07:  # CDR_LE, CDR2_LE
        sec = _u32le(p + 4)
        nanosec = _u32le(p + 8)
    elif p[1] == 0x00 or p[1] == 0x06:  # CDR_BE, CDR2_BE
        sec = _u32be(p + 4)
        nanosec = _u32be(p + 8)
    else:
        return None
    if sec > 2147483647 or nanosec >= 1000000000:  # a negative int32 sec; not normalized
        return None
    return _named1(Clock, _time_of(<int64_t>sec * 1000000000 + nanosec))


# -- writing a ROS 1 TFMessage -----------------------------------------------------------

cdef extern from "Python.h":
    const char* PyUnicode_AsUTF8AndSize(object unicode, Py_ssize_t* size) except NULL
    double PyFloat_AS_DOUBLE(object o)
    object PyBytes_FromStringAndSize(const char* v, Py_ssize_t size)

DEF _SEC_MAX = 2147483647  # ROS 1 time as written: 0 .. 2**31-1 s (rosbags' int32)
DEF _ONE_FIXED = 16 + 4 + 56  # seq, secs, nsecs, len(frame_id); len(child); 7 float64


cdef inline char* _put_u32(char* p, uint32_t v) noexcept:
    p[0] = <char> (v & 0xFF)
    p[1] = <char> ((v >> 8) & 0xFF)
    p[2] = <char> ((v >> 16) & 0xFF)
    p[3] = <char> ((v >> 24) & 0xFF)
    return p + 4


cdef inline char* _put_f64(char* p, double d) noexcept:
    cdef uint64_t bits
    cdef int i
    memcpy(&bits, &d, 8)
    for i in range(8):
        p[i] = <char> ((bits >> (8 * i)) & 0xFF)
    return p + 8


cdef inline int64_t _common_form(object ts, Py_ssize_t* parent_len, Py_ssize_t* child_len) except -2:
    """The stamp (int ns, ``>= 0``) of ``ts`` when it has the common form both writers
    write: a ``TransformStamped`` of the message classes themselves (no subclass), a
    ``Time`` stamp holding an int in [0, 2**63), ``str`` ids that are UTF-8 (their
    lengths in bytes put in ``parent_len`` and ``child_len``: the UTF-8 CPython keeps in
    the str, made once per str, none for ASCII) and seven ``float`` values; -1 for
    anything else."""
    cdef object header, stamp, parent, child, held
    cdef int64_t ns
    if type(ts) is not TransformStamped or len(<tuple>ts) != 3:
        return -1
    header = (<tuple>ts)[0]
    child = (<tuple>ts)[1]
    if type(header) is not Header or len(<tuple>header) != 2:
        return -1
    stamp = (<tuple>header)[0]
    parent = (<tuple>header)[1]
    if type(stamp) is not Time or type(parent) is not str or type(child) is not str:
        return -1
    if not _plain_values((<tuple>ts)[2]):
        return -1
    held = stamp._ns
    if type(held) is not int:
        return -1  # not a Time as Time makes it
    try:
        ns = held
    except OverflowError:
        return -1
    if ns < 0:
        return -1
    try:
        PyUnicode_AsUTF8AndSize(parent, parent_len)
        PyUnicode_AsUTF8AndSize(child, child_len)
    except UnicodeEncodeError:  # a lone surrogate
        return -1
    return ns


def _tf_to_ros1(transforms, bint framed):
    """The ROS 1 ``TFMessage`` bytes of ``transforms`` (``framed``: the TCPROS ``uint32``
    length first), as :func:`tfbus.codecs.ros1._encode_struct` writes them (roscpp's
    layout: ``uint32`` count, then per transform ``seq`` 0, ``secs``, ``nsecs``,
    ``frame_id``, ``child_frame_id`` as ``uint32`` length + UTF-8, seven ``float64``;
    little endian), for its common form: a list or tuple of ``TransformStamped`` of the
    message classes themselves, ``str`` ids that are UTF-8, seven ``float`` values, a
    ``Time`` stamp within ROS 1's 0 .. 2**31-1 s. None for anything else: the Python
    writer then writes it (it converts with ``float()``) or names what is wrong. Each
    id's UTF-8 is the one CPython keeps in the str (made once per str, none for ASCII)."""
    cdef Py_ssize_t n, k, size, total = 4
    cdef Py_ssize_t parent_len, child_len
    cdef object ts, header, child, tf, tr, rot
    cdef const char* parent_utf8
    cdef const char* child_utf8
    cdef int64_t ns
    cdef char* p
    if type(transforms) is not list and type(transforms) is not tuple:
        return None
    n = len(transforms)
    for k in range(n):
        ns = _common_form(transforms[k], &parent_len, &child_len)
        if ns < 0 or ns // 1000000000 > _SEC_MAX:
            return None  # the Python writer writes it or names what is wrong
        total += _ONE_FIXED + parent_len + child_len
    data = PyBytes_FromStringAndSize(NULL, total + 4 if framed else total)
    p = PyBytes_AS_STRING(data)
    if framed:
        p = _put_u32(p, <uint32_t> total)
    p = _put_u32(p, <uint32_t> n)
    for k in range(n):
        ts = transforms[k]
        header = (<tuple>ts)[0]
        child = (<tuple>ts)[1]
        ns = (<tuple>header)[0]._ns
        parent_utf8 = PyUnicode_AsUTF8AndSize((<tuple>header)[1], &parent_len)
        child_utf8 = PyUnicode_AsUTF8AndSize(child, &child_len)
        p = _put_u32(p, 0)  # seq
        p = _put_u32(p, <uint32_t> (ns // 1000000000))
        p = _put_u32(p, <uint32_t> (ns % 1000000000))
        p = _put_u32(p, <uint32_t> parent_len)
        memcpy(p, parent_utf8, parent_len)
        p += parent_len
        p = _put_u32(p, <uint32_t> child_len)
        memcpy(p, child_utf8, child_len)
        p += child_len
        tf = (<tuple>ts)[2]
        tr = (<tuple>tf)[0]
        rot = (<tuple>tf)[1]
        for size in range(3):
            p = _put_f64(p, PyFloat_AS_DOUBLE((<tuple>tr)[size]))
        for size in range(4):
            p = _put_f64(p, PyFloat_AS_DOUBLE((<tuple>rot)[size]))
    return data


# -- writing a TFMessage payload of tfbus's own wire ----------------------------------------

cdef inline Py_ssize_t _uint_size(uint64_t v) noexcept:
    """Bytes of msgpack's shortest form of the unsigned integer ``v`` (positive fixint,
    uint 8, 16, 32, 64), as msgspec writes a non-negative int."""
    if v < 0x80:
        return 1
    if v < 0x100:
        return 2
    if v < 0x10000:
        return 3
    if v < 0x100000000:
        return 5
    return 9


cdef inline char* _put_be(char* p, uint64_t v, int n) noexcept:
    """The ``n`` low bytes of ``v``, big-endian (msgpack's order)."""
    cdef int i
    for i in range(n):
        p[i] = <char> ((v >> (8 * (n - 1 - i))) & 0xFF)
    return p + n


cdef inline char* _put_uint(char* p, uint64_t v) noexcept:
    """``v`` in msgpack's shortest unsigned form (:func:`_uint_size` bytes)."""
    if v < 0x80:
        p[0] = <char> v
        return p + 1
    if v < 0x100:
        p[0] = <char> 0xcc
        return _put_be(p + 1, v, 1)
    if v < 0x10000:
        p[0] = <char> 0xcd
        return _put_be(p + 1, v, 2)
    if v < 0x100000000:
        p[0] = <char> 0xce
        return _put_be(p + 1, v, 4)
    p[0] = <char> 0xcf
    return _put_be(p + 1, v, 8)


cdef inline Py_ssize_t _head_size(Py_ssize_t n, Py_ssize_t fixed) noexcept:
    """Bytes of the head of a msgpack str (``fixed`` 32) or array (``fixed`` 16) of
    length ``n``: its fix form below ``fixed``, then the 8- (str only), 16- and 32-bit
    forms, as msgspec writes them."""
    if n < fixed:
        return 1
    if fixed == 32 and n < 0x100:
        return 2
    if n < 0x10000:
        return 3
    return 5


cdef inline char* _put_head(char* p, Py_ssize_t n, Py_ssize_t fixed) noexcept:
    """The head :func:`_head_size` counts: of a str (``fixed`` 32: fixstr ``0xa0 | n``, str
    8, 16, 32 ``0xd9``-``0xdb``) or an array (``fixed`` 16: fixarray ``0x90 | n``, array
    16, 32 ``0xdc``, ``0xdd``) of length ``n``."""
    cdef bint text = fixed == 32
    if n < fixed:
        p[0] = <char> ((0xa0 if text else 0x90) | n)
        return p + 1
    if text and n < 0x100:
        p[0] = <char> 0xd9
        return _put_be(p + 1, <uint64_t> n, 1)
    if n < 0x10000:
        p[0] = <char> (0xda if text else 0xdc)
        return _put_be(p + 1, <uint64_t> n, 2)
    p[0] = <char> (0xdb if text else 0xdd)
    return _put_be(p + 1, <uint64_t> n, 4)


cdef inline char* _put_f64_be(char* p, double d) noexcept:
    """A msgpack float 64 (``0xcb``, then the IEEE 754 bits big-endian), as msgspec writes
    every Python float."""
    cdef uint64_t bits
    memcpy(&bits, &d, 8)
    p[0] = <char> 0xcb
    return _put_be(p + 1, bits, 8)


DEF _NATIVE_FIXED = 1 + 1 + 1 + 1 + 4 * 9 + 1 + 3 * 9  # a transform's heads and floats


def _tf_to_native(transforms, sender, seq, int magic, int version):
    """The tfbus wire payload of a TFMessage of ``transforms`` from ``sender`` with
    sequence number ``seq`` (``magic``, ``version``, then the msgpack array ``[sender,
    seq, "tf", body]``), byte for byte what :meth:`tfbus.codecs.native.WireCodec.encode`
    has msgspec write (tested), for the common form: a list or tuple of
    ``TransformStamped`` of the message classes themselves, ``str`` ids that are UTF-8,
    seven ``float`` values, a ``Time`` stamp, an ``int`` sender and sequence number in
    [0, 2**64). msgspec's forms: each NamedTuple an array of its fields, a stamp its int
    nanoseconds, every int and the length of every str and array in its shortest form,
    every float a float 64. None for anything else: msgspec then writes it, or says what
    cannot be written. Each id's UTF-8 is the one CPython keeps in the str, as in
    :func:`_tf_to_ros1`."""
    cdef Py_ssize_t n, k, i, total, parent_len, child_len
    cdef object ts, header, child, tf, tr, rot
    cdef const char* parent_utf8
    cdef const char* child_utf8
    cdef int64_t ns
    cdef uint64_t who, number
    cdef char* p
    if type(transforms) is not list and type(transforms) is not tuple:
        return None
    if type(sender) is not int or type(seq) is not int:
        return None
    try:
        who = sender
        number = seq
    except OverflowError:  # negative, or 2**64 or more: msgspec writes or names it
        return None
    n = len(transforms)
    total = 2 + 1 + _uint_size(who) + _uint_size(number) + 3 + _head_size(n, 16)
    for k in range(n):
        ns = _common_form(transforms[k], &parent_len, &child_len)
        if ns < 0:
            return None  # msgspec writes it or names what cannot be written
        total += (_NATIVE_FIXED + _uint_size(<uint64_t> ns) + _head_size(parent_len, 32)
                  + parent_len + _head_size(child_len, 32) + child_len)
    data = PyBytes_FromStringAndSize(NULL, total)
    p = PyBytes_AS_STRING(data)
    p[0] = <char> magic
    p[1] = <char> version
    p[2] = <char> 0x94  # [sender, seq, tag, body]
    p = _put_uint(p + 3, who)
    p = _put_uint(p, number)
    p[0] = <char> 0xa2  # "tf"
    p[1] = <char> 0x74
    p[2] = <char> 0x66
    p = _put_head(p + 3, n, 16)
    for k in range(n):
        ts = transforms[k]
        header = (<tuple>ts)[0]
        child = (<tuple>ts)[1]
        ns = (<tuple>header)[0]._ns
        parent_utf8 = PyUnicode_AsUTF8AndSize((<tuple>header)[1], &parent_len)
        child_utf8 = PyUnicode_AsUTF8AndSize(child, &child_len)
        p[0] = <char> 0x93  # [header, child_frame_id, transform]
        p[1] = <char> 0x92  # [stamp, frame_id]
        p = _put_uint(p + 2, <uint64_t> ns)
        p = _put_head(p, parent_len, 32)
        memcpy(p, parent_utf8, parent_len)
        p = _put_head(p + parent_len, child_len, 32)
        memcpy(p, child_utf8, child_len)
        p += child_len
        tf = (<tuple>ts)[2]
        tr = (<tuple>tf)[0]
        rot = (<tuple>tf)[1]
        p[0] = <char> 0x92  # [translation, rotation]
        p[1] = <char> 0x93
        p += 2
        for i in range(3):
            p = _put_f64_be(p, PyFloat_AS_DOUBLE((<tuple>tr)[i]))
        p[0] = <char> 0x94
        p += 1
        for i in range(4):
            p = _put_f64_be(p, PyFloat_AS_DOUBLE((<tuple>rot)[i]))
    return data

# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, embedsignature=True
"""ROS 1 wire, compiled: ``_tf_from_ros1`` turns a ROS 1 serialised ``TFMessage`` into
TransformStamped values, built in C like the lookups' results (the fast path of
``tfbus.bag.decode.decode_ros1``; the pure-Python decoder there is its twin)."""

from cpython.float cimport PyFloat_FromDouble
from cpython.object cimport PyObject
from cpython.ref cimport Py_DECREF, Py_INCREF
from libc.string cimport memcpy
from cpython.unicode cimport PyUnicode_GET_LENGTH
from libc.stdint cimport int64_t

from tfbus.core._ccore cimport _time_of
from tfbus.core._cresults cimport PyObject_GC_UnTrack, _named, _named3, _named4
from tfbus.messages import Header, Quaternion, Transform, TransformStamped, Vector3
from tfbus.time import Time

from struct import error as _StructError

from cpython.list cimport PyList_New, PyList_SET_ITEM
from cpython.unicode cimport PyUnicode_DecodeUTF8
from libc.stdint cimport uint32_t
from libc.string cimport memcmp


cdef extern from "Python.h":
    int PyUnicode_IS_ASCII(object o)
    void* PyUnicode_DATA(object o)


# Frame ids by their position in a message: a publisher sends the same ids message
# after message, so an id whose bytes equal the ASCII str decoded last time at the same
# position is that (immutable) str again, not a new one. Compared byte for byte on
# every use; a different id replaces it. Positions past _ROS1_ID_SLOTS are decoded.
DEF _ROS1_ID_SLOTS = 4096
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
    if k < _ROS1_ID_SLOTS and PyUnicode_IS_ASCII(text):
        cache[k] = text
    return text


# Transform values by their position in a message, alike: a publisher sends many of the
# same values message after message (robot_state_publisher's joint origins, identity
# rotations, a robot standing still), so a Transform, Vector3 or Quaternion whose 56, 24
# or 32 bytes equal those decoded last time at the same position is that (immutable)
# value again, not new floats and tuples. Compared byte for byte (so 0.0 and -0.0, or two
# NaN payloads, are told apart) on every use; different bytes replace it.
cdef list _ros1_transforms = [None] * _ROS1_ID_SLOTS
cdef double _ros1_values[_ROS1_ID_SLOTS][7]


cdef inline object _ros1_transform(Py_ssize_t k, const double* v):
    """The Transform of the 7 doubles ``v`` (translation x y z, rotation x y z w): the
    one cached at ``k``, or one sharing its Vector3 or Quaternion, when the bytes match."""
    cdef object cached = None, vec = None, rot = None, tf
    cdef double* old
    if k < _ROS1_ID_SLOTS:
        cached = _ros1_transforms[k]
        if cached is not None:
            old = _ros1_values[k]
            if memcmp(old, v, 7 * sizeof(double)) == 0:
                return cached
            if memcmp(old, v, 3 * sizeof(double)) == 0:
                vec = (<tuple>cached)[0]
            elif memcmp(old + 3, v + 3, 4 * sizeof(double)) == 0:
                rot = (<tuple>cached)[1]
    if vec is None:
        vec = _named3(Vector3, PyFloat_FromDouble(v[0]), PyFloat_FromDouble(v[1]),
                      PyFloat_FromDouble(v[2]))
        PyObject_GC_UnTrack(<PyObject*>vec)  # three floats: never part of a cycle
    if rot is None:
        rot = _named4(Quaternion, v[3], v[4], v[5], v[6])
    tf = _named(Transform, vec, rot)
    PyObject_GC_UnTrack(<PyObject*>tf)  # two untracked tuples: never part of a cycle
    if k < _ROS1_ID_SLOTS:
        _ros1_transforms[k] = tf
        memcpy(_ros1_values[k], v, 7 * sizeof(double))
    return tf


cdef inline uint32_t _u32le(const unsigned char* p) noexcept:
    return <uint32_t>p[0] | (<uint32_t>p[1] << 8) | (<uint32_t>p[2] << 16) | (<uint32_t>p[3] << 24)


cdef enum:
    _ROS1_TF_MIN = 76  # bytes of a transform with empty ids: 4 u32 + 2 u32 + 7 float64


def _tf_from_ros1(const unsigned char[::1] buf):
    """The transforms of a ROS 1 serialised ``tf2_msgs/TFMessage`` (``u32 count``, then
    per transform ``u32 seq, u32 sec, u32 nsec, u32 len, frame_id, u32 len,
    child_frame_id, 7 float64``, little endian), built in C: what
    ``tfbus.bag.decode.decode_ros1``'s struct decoder returns, equal values (frame ids
    decoded as strict UTF-8; a transform whose serialised header is byte for byte the
    previous one's shares its Header; an ASCII frame id equal to the one at the same
    position of an earlier message is that message's str, not a new one, and a transform
    whose 7 doubles (or translation, or rotation) are byte for byte those at the same
    position of the last message is that message's Transform (Vector3, Quaternion);
    bytes after the last transform are ignored).
    Little-endian hosts only (the doubles are read in host order).

    Raises:
        struct.error: the payload is shorter than its contents.
        UnicodeDecodeError: a frame id is not UTF-8.
    """
    cdef Py_ssize_t size = buf.shape[0], off = 4, head, hlen = 0, prev = -1, k
    cdef const unsigned char* p
    cdef uint32_t n, flen, clen, sec, nsec
    cdef double v[7]
    cdef object header = None, child, ts
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
        ts = _named3(TransformStamped, header, child, _ros1_transform(k, v))
        out[k] = ts
    return out

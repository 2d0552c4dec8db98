# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, embedsignature=True
# The core's results built in C (NamedTuples without their Python-level ``__new__``),
# shared by the walk (``_ccore``, which also builds ``_stamped`` / ``_time_of`` from them)
# and the ROS 1 decoder (``_cwire``).

from cpython.float cimport PyFloat_FromDouble
from cpython.object cimport PyObject
from cpython.ref cimport Py_DECREF, Py_INCREF
from cpython.tuple cimport PyTuple_SET_ITEM

cdef extern from "Python.h":
    ctypedef PyObject* (*allocfunc)(PyTypeObject* tp, Py_ssize_t n) except NULL
    ctypedef struct PyTypeObject:
        allocfunc tp_alloc
    PyObject* PyType_GenericAlloc(PyTypeObject* tp, Py_ssize_t n) except NULL
    int PyObject_GenericSetAttr(object o, object name, object value) except -1
    void PyObject_GC_UnTrack(void* op)


cdef inline object _named1(object cls, object a):
    """``tuple.__new__(cls, (a,))`` for a NamedTuple class of one field."""
    cdef PyObject* p = PyType_GenericAlloc(<PyTypeObject*>cls, 1)
    cdef object obj = <object>p
    Py_DECREF(obj)
    Py_INCREF(a)
    PyTuple_SET_ITEM(obj, 0, a)
    return obj


cdef inline object _named(object cls, object a, object b):
    """``tuple.__new__(cls, (a, b))`` for a NamedTuple class, without its Python-level
    ``__new__`` (what ``tuple_subtype_new`` does, minus the argument tuple)."""
    cdef PyObject* p = PyType_GenericAlloc(<PyTypeObject*>cls, 2)
    cdef object obj = <object>p
    Py_DECREF(obj)
    Py_INCREF(a)
    Py_INCREF(b)
    PyTuple_SET_ITEM(obj, 0, a)
    PyTuple_SET_ITEM(obj, 1, b)
    return obj


cdef inline object _named3(object cls, object a, object b, object c):
    cdef PyObject* p = PyType_GenericAlloc(<PyTypeObject*>cls, 3)
    cdef object obj = <object>p
    Py_DECREF(obj)
    Py_INCREF(a)
    Py_INCREF(b)
    Py_INCREF(c)
    PyTuple_SET_ITEM(obj, 0, a)
    PyTuple_SET_ITEM(obj, 1, b)
    PyTuple_SET_ITEM(obj, 2, c)
    return obj


cdef inline object _named5(object cls, object a, object b, object c, object d, object e):
    cdef PyObject* p = PyType_GenericAlloc(<PyTypeObject*>cls, 5)
    cdef object obj = <object>p
    Py_DECREF(obj)
    Py_INCREF(a)
    Py_INCREF(b)
    Py_INCREF(c)
    Py_INCREF(d)
    Py_INCREF(e)
    PyTuple_SET_ITEM(obj, 0, a)
    PyTuple_SET_ITEM(obj, 1, b)
    PyTuple_SET_ITEM(obj, 2, c)
    PyTuple_SET_ITEM(obj, 3, d)
    PyTuple_SET_ITEM(obj, 4, e)
    return obj


cdef inline object _named4(object cls, double a, double b, double c, double d):
    cdef PyObject* p = PyType_GenericAlloc(<PyTypeObject*>cls, 4)
    PyObject_GC_UnTrack(p)  # four floats: it can never be part of a reference cycle
    cdef object obj = <object>p
    cdef object fa = PyFloat_FromDouble(a)
    cdef object fb = PyFloat_FromDouble(b)
    cdef object fc = PyFloat_FromDouble(c)
    cdef object fd = PyFloat_FromDouble(d)
    Py_DECREF(obj)
    Py_INCREF(fa)
    Py_INCREF(fb)
    Py_INCREF(fc)
    Py_INCREF(fd)
    PyTuple_SET_ITEM(obj, 0, fa)
    PyTuple_SET_ITEM(obj, 1, fb)
    PyTuple_SET_ITEM(obj, 2, fc)
    PyTuple_SET_ITEM(obj, 3, fd)
    return obj

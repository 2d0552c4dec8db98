# cython: language_level=3
# The delay arithmetic shared by the compiled accounting of tf_monitor's tables
# (``tfbus/_cmonitor.pyx``) and of the doctor's checks (``tfbus/doctor/_cchecks.pyx``),
# inlined into each: a difference of int nanoseconds in seconds, as their Python loops
# compute it (``diff / NSEC_PER_SEC``).

from cpython.long cimport PyLong_AsLongLongAndOverflow


cdef inline double delay_seconds(object diff) except? -1.0:
    """``diff / NSEC_PER_SEC`` (``tfbus.time``: 10**9) as Python computes it, for ``diff``
    an int of nanoseconds. A ``diff`` a double holds exactly (an int of at most 53 bits)
    is divided in C: one correctly rounded division of two exactly held doubles, the
    quotient Python's true division of two ints gives; any other ``diff`` (wider, or not
    an int) is divided by Python.

    Raises:
        Exception: what ``diff / NSEC_PER_SEC`` raises.
    """
    cdef int overflow = 1
    cdef long long di = 0
    if type(diff) is int:
        di = PyLong_AsLongLongAndOverflow(diff, &overflow)
    if overflow == 0 and -(1LL << 53) <= di <= (1LL << 53):
        return <double>di / 1e9
    return diff / 1_000_000_000

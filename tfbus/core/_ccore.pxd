# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, embedsignature=True
# Declarations of the compiled frame table and walk (``_ccore.pyx``), for the batch
# kernel (``_cbatch``), which reads the table and calls the walk for rows it cannot plan.

from libc.stdint cimport int64_t

cdef enum:
    # Slots of the lookup memo (a power of two). Small: a memo holds results alive.
    MEMO_SIZE = 64


cdef class CoreBase:
    cdef readonly dict _frame_ids
    cdef readonly list _frame_names
    cdef readonly list _caches
    cdef readonly dict _authority
    cdef readonly long long _generation
    cdef int64_t _cache_ns
    cdef bint _replace_repeated
    cdef list _memo
    cdef int64_t _memo_t[MEMO_SIZE]
    cdef long long _memo_gen[MEMO_SIZE]
    cdef str _last_parent
    cdef str _last_child
    cdef int64_t _last_stamp
    cdef object _last_values
    cdef bint _last_relinked
    cdef list _free
    cdef list _refs
    cdef list _lparents
    cdef list _heap
    cdef int64_t _newest
    cdef bint _expiring
    cdef int64_t _expire_ns
    cdef int64_t _expire_every
    cdef int64_t _expire_due
    cdef long long _frames_expired
    cdef dict _waits
    cdef object _batch
    cdef list _settled
    cdef object _register(self, str frame_id)
    cdef int _name_parent(self, object cid, object pid) except -1
    cdef int _unregister(self, object fid) except -1
    cdef int _expire(self) except -1
    cdef Py_ssize_t _cforget(self, int64_t older_than) except -1
    cdef int _insert_one(self, object ts, str authority, bint is_static) except -1
    cdef object _problem(self, int code)
    cdef object _csettle(self, dict index, object names)
    cdef list _settle_one(self, object waiter, dict index, list settled, list rest)
    cdef object _cstore(self, object transforms, str authority, bint is_static)
    cdef object _cquery(self, object target, object source, object time)
    cdef int _common(self, int target, int source, int64_t* out) except -1
    cdef int _walk(self, int target_id, int source_id, int64_t* time, double* out,
                   int* where) except -1
    cdef int _walk_policy(self, int target_id, int source_id, int64_t* time, int mode,
                          int64_t before, int64_t after, double* out, int* where,
                          int* sf, int64_t* ss, Py_ssize_t* n) except -1

    cdef inline int _frame(self, object frame_id) except -2:
        """Id of a known, queryable frame, or -1 (empty, '/'-prefixed, unknown)."""
        cdef object fid = self._frame_ids.get(frame_id)
        if fid is None or <int>fid == 0:
            return -1
        if type(frame_id) is not str or not len(<str>frame_id) or (<str>frame_id)[0] == "/":
            return -1
        return <int>fid


cdef int _climb(list caches, int frame, int stop, int early, int64_t time, double* acc,
                int* reached) except -1

cdef object _time_of(int64_t ns)
cdef bint _plain_values(object tf) noexcept

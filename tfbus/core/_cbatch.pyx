# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, embedsignature=True
"""The batched lookups' kernel, compiled: ``batch_lookup`` / ``lookup_rows`` resolve the
path between two frames once and gather and accumulate every link for every time in C,
in blocks of SIMD lanes, on up to two threads, with slerp's per-time sines from glibc's
libmvec (loaded with :mod:`ctypes`) where available. The twin of
:mod:`tfbus.core._pybatch`; reads the frame table (``_ccore.pxd``) and the caches' arrays
(``_ccache.pxd``) and calls the walk for rows it cannot plan."""

__all__ = [
    "batch_lookup",
    "lookup_rows",
]

import numpy as np

from libc.math cimport acos, fabs, sin, sqrt
from libc.stdint cimport INT64_MAX, int32_t, int64_t, uint64_t
from libc.string cimport memcpy

from tfbus.core._ccache cimport C_MAX_DEPTH, G_OK, Link, StaticCache, TimeCache, _link
from tfbus.core._ccore cimport CoreBase, _climb
from tfbus.core._cmath cimport EXACT_SPAN, _bisect_left, _compose, _identity, _slerp

from tfbus.core._ccore import NO_ERROR

# ===== batched lookups =====
#
# ``batch_lookup`` answers ``lookup_transform`` for many times at once. The path between
# the two frames is resolved once (the same climbs as ``_cwalk``, by each link's parent);
# then every time is gathered and accumulated along it in C, in ``_cwalk``'s arithmetic
# order (only the slerp angle and 1/sin of an interval are reused between the times that
# fall in it, which is exact). Rows are walked in blocks of 32, one row per lane
# (structure of arrays), so the composition runs in SIMD lanes with the scalar
# expressions (no FMA contraction: same bits). The one inexact step: slerp's two
# per-time sines come from libmvec's vector sin where it is available
# (``_batch_lookup_vector``, if ``_BATCH_VECTOR_SIN``), a few ulp from libm's, so such
# rows agree with the single
# lookup to ~1e-15 (the batch tolerance is 1e-12), not bit for bit; rows without a per-time
# sine (exact stamps, statics, zero slerp angles), and every row where libmvec is not
# used, are the single lookup's bit for bit. Rows the plan cannot answer
# exactly (time 0, a gather that fails, a link with several parents, a span >= 2**53 ns)
# go through ``CoreBase._walk``; rows that fail there too are left unanswered, and
# ``tfbus.core.batch`` asks the single lookup for tf2's exception: no error is reproduced.

import atexit
import os
from time import perf_counter_ns

from libc.string cimport memset
from libc.stdlib cimport free, malloc
from cpython.pythread cimport (
    WAIT_LOCK,
    PyThread_acquire_lock,
    PyThread_allocate_lock,
    PyThread_free_lock,
    PyThread_release_lock,
    PyThread_start_new_thread,
    PyThread_type_lock,
)

cdef extern from "pythread.h":
    # CPython's lock free needs no GIL (it frees with PyMem_RawFree); Cython's
    # declaration of it lacks ``nogil``.
    void _free_lock_nogil "PyThread_free_lock"(PyThread_type_lock lock) noexcept nogil
    ctypedef enum PyLockStatus:
        PY_LOCK_FAILURE
        PY_LOCK_ACQUIRED
        PY_LOCK_INTR
    PyLockStatus PyThread_acquire_lock_timed(PyThread_type_lock lock, long long microseconds,
                                             int intr_flag) noexcept nogil

cdef int _NCPU = os.cpu_count() or 1
cdef Py_ssize_t _SPLIT_ROWS = 8192  # below this a second thread costs more than it saves
cdef int _SPLIT_BACKOFF_MAX = 64  # calls on one thread after repeated losing splits
cdef int _split_skip = 0  # calls left to run on one thread (GIL held when read or set)
cdef int _split_backoff = 0  # the last skip given; doubles while splits keep losing


cdef int _split_verdict(int64_t wall_ns, int64_t own_ns, Py_ssize_t own_rows,
                        Py_ssize_t n_rows, bint worker_ran) noexcept:
    """After a two-thread call: whether it lost to one thread, and if so, how many calls
    to run on one thread before trying two again (1, 2, 4, ... up to 64 while the splits
    keep losing; 0 after a winning one). One thread's wall time is estimated from the
    caller's own pace (``own_ns`` for ``own_rows`` rows, the second thread's start
    included); a worker that never started (no core free) counts as a loss. GIL held."""
    global _split_skip, _split_backoff
    cdef bint lost = not worker_ran or own_rows <= 0 or (
        <double>wall_ns > <double>own_ns * <double>n_rows / <double>own_rows)
    if lost:
        _split_backoff = 1 if _split_backoff == 0 else min(2 * _split_backoff,
                                                            _SPLIT_BACKOFF_MAX)
        _split_skip = _split_backoff
    else:
        _split_backoff = 0
        _split_skip = 0
    return _split_skip


def _split_after(wall_ns, own_ns, own_rows, n_rows, worker_ran):
    """:func:`_split_verdict` for white-box tests: the one-thread calls it sets."""
    return _split_verdict(wall_ns, own_ns, own_rows, n_rows, worker_ran)


def _split_reset():
    """Forget past verdicts (white-box tests): the next large call splits again."""
    global _split_skip, _split_backoff
    _split_skip = 0
    _split_backoff = 0
cdef Py_ssize_t _SORT_ROWS = 64  # below this, unsorted times are walked as given


cdef bint _nondecreasing(const int64_t* t, Py_ssize_t n) noexcept nogil:
    """Whether ``t[0] <= t[1] <= ... <= t[n - 1]``."""
    cdef Py_ssize_t i
    for i in range(1, n):
        if t[i] < t[i - 1]:
            return False
    return True


cdef bint _nonincreasing(const int64_t* t, Py_ssize_t n) noexcept nogil:
    """Whether ``t[0] >= t[1] >= ... >= t[n - 1]``."""
    cdef Py_ssize_t i
    for i in range(1, n):
        if t[i] > t[i - 1]:
            return False
    return True


cdef tuple _bsorted(const int64_t[::1] times):
    """The ``n`` times in non-decreasing order and, for each, its row in ``times`` (two
    ``(n,) int64`` arrays; a row's value does not depend on the order it is walked in, so
    equal times may come in any order). Non-increasing times are read backwards (no
    sort). Otherwise, when ``(max - min) * 2**b`` fits in 63 bits (``b`` bits number the
    rows), each time becomes one key ``(t - min) << b | row`` and numpy sorts the keys
    (its SIMD sort of int64: ~3x faster than ``argsort`` on 10 000 times); else
    ``np.argsort``."""
    cdef Py_ssize_t n = times.shape[0], i
    cdef int64_t lo, hi
    cdef uint64_t span, mask
    cdef int bits = 0
    out_t = np.empty(n, dtype=np.int64)
    out_r = np.empty(n, dtype=np.int64)
    cdef int64_t[::1] ts = out_t
    cdef int64_t[::1] rs = out_r
    cdef int64_t[::1] keys
    if _nonincreasing(&times[0], n):
        for i in range(n):
            ts[i] = times[n - 1 - i]
            rs[i] = n - 1 - i
        return out_t, out_r
    lo = hi = times[0]
    for i in range(1, n):
        if times[i] < lo:
            lo = times[i]
        elif times[i] > hi:
            hi = times[i]
    while (<uint64_t>1 << bits) < <uint64_t>n:
        bits += 1
    span = <uint64_t>hi - <uint64_t>lo
    if bits < 63 and span < (<uint64_t>1 << (63 - bits)):
        mask = (<uint64_t>1 << bits) - 1
        packed = np.empty(n, dtype=np.int64)
        keys = packed
        for i in range(n):
            keys[i] = <int64_t>(((<uint64_t>times[i] - <uint64_t>lo) << bits) | <uint64_t>i)
        packed.sort(kind="quicksort")  # keys are distinct: the order is unique
        for i in range(n):
            ts[i] = <int64_t>((<uint64_t>keys[i] >> bits) + <uint64_t>lo)
            rs[i] = <int64_t>(<uint64_t>keys[i] & mask)
        return out_t, out_r
    arr = np.asarray(times)
    order = np.argsort(arr, kind="quicksort").astype(np.int64, copy=False)
    return arr.take(order), order


cdef extern from *:
    """
    /* tfbus batched lookups: the element-wise kernels over a block of rows (structure of
       arrays, one row per lane) and the atomics of the two-thread split. Plain IEEE
       double expressions in tf2's evaluation order; the extension is compiled with
       -ffp-contract=off, so vectorised lanes round exactly as the scalar walk does. */
    #define TFB_BLOCK 32
    /* The block kernels in AVX2 lanes too where GCC can dispatch at load time (ifunc):
       vector or scalar, each lane is the same IEEE expression (no FMA contraction). */
    #if defined(__GNUC__) && !defined(__clang__) && __GNUC__ >= 6 && defined(__x86_64__) \
        && defined(__linux__)
    #define TFB_CLONES __attribute__((target_clones("avx2", "default")))
    #else
    #define TFB_CLONES
    #endif
    #if defined(__GNUC__) || defined(__clang__)
    #define TFB_RESTRICT __restrict__
    #elif defined(_MSC_VER)
    #define TFB_RESTRICT __restrict
    #else
    #define TFB_RESTRICT
    #endif

    /* acc = link o acc for every lane: tf2 TransformAccum::accum / quatRotate and
       Quaternion operator* (the expressions of _qrot, _qmul, _compose, same order). */
    static TFB_CLONES void tfb_compose_block(double (*TFB_RESTRICT acc)[TFB_BLOCK],
                                  const double (*TFB_RESTRICT st)[TFB_BLOCK]) {
        int j;
        for (j = 0; j < TFB_BLOCK; j++) {
            double qx = st[3][j], qy = st[4][j], qz = st[5][j], qw = st[6][j];
            double vx = acc[0][j], vy = acc[1][j], vz = acc[2][j];
            double bx = acc[3][j], by = acc[4][j], bz = acc[5][j], bw = acc[6][j];
            double tx = qw * vx + qy * vz - qz * vy;
            double ty = qw * vy + qz * vx - qx * vz;
            double tz = qw * vz + qx * vy - qy * vx;
            double tw = -qx * vx - qy * vy - qz * vz;
            acc[0][j] = (-tw * qx + tx * qw - ty * qz + tz * qy) + st[0][j];
            acc[1][j] = (-tw * qy + ty * qw - tz * qx + tx * qz) + st[1][j];
            acc[2][j] = (-tw * qz + tz * qw - tx * qy + ty * qx) + st[2][j];
            acc[3][j] = qw * bx + qx * bw + qy * bz - qz * by;
            acc[4][j] = qw * by + qy * bw + qz * bx - qx * bz;
            acc[5][j] = qw * bz + qz * bw + qx * by - qy * bx;
            acc[6][j] = qw * bw - qx * bx - qy * by - qz * bz;
        }
    }

    /* _cwalk's FullPath step for every lane (tf2 BufferCore::walkToTopParent, FullPath:
       inverse(target -> top) * (source -> top)), the expressions of _bfull. */
    static TFB_CLONES void tfb_full_block(const double (*TFB_RESTRICT src)[TFB_BLOCK],
                               const double (*TFB_RESTRICT tgt)[TFB_BLOCK],
                               double (*TFB_RESTRICT out)[TFB_BLOCK]) {
        int j;
        for (j = 0; j < TFB_BLOCK; j++) {
            double sqx = src[3][j], sqy = src[4][j], sqz = src[5][j], sqw = src[6][j];
            double iqx = -tgt[3][j], iqy = -tgt[4][j], iqz = -tgt[5][j], iqw = tgt[6][j];
            double vx = src[0][j] - tgt[0][j], vy = src[1][j] - tgt[1][j];
            double vz = src[2][j] - tgt[2][j];
            double tx = iqw * vx + iqy * vz - iqz * vy;
            double ty = iqw * vy + iqz * vx - iqx * vz;
            double tz = iqw * vz + iqx * vy - iqy * vx;
            double tw = -iqx * vx - iqy * vy - iqz * vz;
            out[0][j] = -tw * iqx + tx * iqw - ty * iqz + tz * iqy;
            out[1][j] = -tw * iqy + ty * iqw - tz * iqx + tx * iqz;
            out[2][j] = -tw * iqz + tz * iqw - tx * iqy + ty * iqx;
            out[3][j] = iqw * sqx + iqx * sqw + iqy * sqz - iqz * sqy;
            out[4][j] = iqw * sqy + iqy * sqw + iqz * sqx - iqx * sqz;
            out[5][j] = iqw * sqz + iqz * sqw + iqx * sqy - iqy * sqx;
            out[6][j] = iqw * sqw - iqx * sqx - iqy * sqy - iqz * sqz;
        }
    }

    #if defined(_MSC_VER) && !defined(__clang__)
    #include <intrin.h>
    static long tfb_fetch_add(long* p, long v) {
        return _InterlockedExchangeAdd((volatile long*)p, v);
    }
    static int tfb_cas(long* p, long expected, long desired) {
        return _InterlockedCompareExchange((volatile long*)p, desired, expected) == expected;
    }
    static void* tfb_xchg(void** p, void* v) {
        return _InterlockedExchangePointer((void* volatile*)p, v);
    }
    #else
    static long tfb_fetch_add(long* p, long v) {
        return __atomic_fetch_add(p, v, __ATOMIC_SEQ_CST);
    }
    static int tfb_cas(long* p, long expected, long desired) {
        return __atomic_compare_exchange_n(p, &expected, desired, 0, __ATOMIC_SEQ_CST,
                                           __ATOMIC_SEQ_CST);
    }
    static void* tfb_xchg(void** p, void* v) {
        return __atomic_exchange_n(p, v, __ATOMIC_SEQ_CST);
    }
    #endif

    #include <math.h>
    #include <stdint.h>
    #if (defined(__GNUC__) || defined(__clang__)) && defined(__x86_64__)
    #define TFB_X86_64 1
    #include <immintrin.h>
    #endif

    /* Rows j0 <= j < j1 of a block, all in one interval (samples a, a + 7; bq = b with
       slerp's sign flip, d = 1 / sin(theta)): TimeCache::interpolate's lerp and tf2 slerp's
       (a sin((1 - r) theta) + b sin(r theta)) / sin(theta), the expressions of
       _binterp_run lane by lane (separate multiplies and adds: no FMA in this target).
       The rows before the first multiple of 4 are computed one by one; from there, whole
       groups of 4 lanes are stored (no masked stores, slow on several x86 cores): lanes
       past j1 in the last group get values that are either never read (a failed row, a
       lane past the block's rows) or overwritten, as the caller fills the block's rows
       in increasing order after this run. */
    static int tfb_avx2 = 0;
    #if defined(TFB_X86_64)
    static __attribute__((target("avx2"))) void tfb_interp_run_avx2(
            const double* a, const double* bq, double d, const double* rr, const double* sy,
            int j0, int j1, double (*st)[TFB_BLOCK]) {
        int j, jv = (j0 + 3) & ~3;
        for (j = j0; j < j1 && j < jv; j++) {
            double r = rr[j], s = 1.0 - r, q0 = sy[j], q1 = sy[TFB_BLOCK + j];
            st[0][j] = s * a[0] + r * a[7];
            st[1][j] = s * a[1] + r * a[8];
            st[2][j] = s * a[2] + r * a[9];
            st[3][j] = (a[3] * q0 + bq[0] * q1) * d;
            st[4][j] = (a[4] * q0 + bq[1] * q1) * d;
            st[5][j] = (a[5] * q0 + bq[2] * q1) * d;
            st[6][j] = (a[6] * q0 + bq[3] * q1) * d;
        }
        if (jv >= j1)
            return;
        const __m256d one = _mm256_set1_pd(1.0), dd = _mm256_set1_pd(d);
        const __m256d a0 = _mm256_set1_pd(a[0]), a1 = _mm256_set1_pd(a[1]);
        const __m256d a2 = _mm256_set1_pd(a[2]), a3 = _mm256_set1_pd(a[3]);
        const __m256d a4 = _mm256_set1_pd(a[4]), a5 = _mm256_set1_pd(a[5]);
        const __m256d a6 = _mm256_set1_pd(a[6]), b0 = _mm256_set1_pd(a[7]);
        const __m256d b1 = _mm256_set1_pd(a[8]), b2 = _mm256_set1_pd(a[9]);
        const __m256d c0 = _mm256_set1_pd(bq[0]), c1 = _mm256_set1_pd(bq[1]);
        const __m256d c2 = _mm256_set1_pd(bq[2]), c3 = _mm256_set1_pd(bq[3]);
        for (j = jv; j < j1; j += 4) {
            __m256d r = _mm256_loadu_pd(rr + j), s = _mm256_sub_pd(one, r);
            __m256d q0 = _mm256_loadu_pd(sy + j), q1 = _mm256_loadu_pd(sy + TFB_BLOCK + j);
            _mm256_storeu_pd(&st[0][j], _mm256_add_pd(_mm256_mul_pd(s, a0), _mm256_mul_pd(r, b0)));
            _mm256_storeu_pd(&st[1][j], _mm256_add_pd(_mm256_mul_pd(s, a1), _mm256_mul_pd(r, b1)));
            _mm256_storeu_pd(&st[2][j], _mm256_add_pd(_mm256_mul_pd(s, a2), _mm256_mul_pd(r, b2)));
            _mm256_storeu_pd(&st[3][j], _mm256_mul_pd(_mm256_add_pd(_mm256_mul_pd(a3, q0), _mm256_mul_pd(c0, q1)), dd));
            _mm256_storeu_pd(&st[4][j], _mm256_mul_pd(_mm256_add_pd(_mm256_mul_pd(a4, q0), _mm256_mul_pd(c1, q1)), dd));
            _mm256_storeu_pd(&st[5][j], _mm256_mul_pd(_mm256_add_pd(_mm256_mul_pd(a5, q0), _mm256_mul_pd(c2, q1)), dd));
            _mm256_storeu_pd(&st[6][j], _mm256_mul_pd(_mm256_add_pd(_mm256_mul_pd(a6, q0), _mm256_mul_pd(c3, q1)), dd));
        }
    }
    #define TFB_INTERP_RUN_AVX2(a, bq, d, rr, sy, j0, j1, st) \
        (tfb_avx2 ? (tfb_interp_run_avx2(a, bq, d, rr, sy, j0, j1, st), 1) : 0)
    #else
    #define TFB_INTERP_RUN_AVX2(a, bq, d, rr, sy, j0, j1, st) 0
    #endif

    /* Every lane of a block: slerp's ratio r = num / den (TimeCache::interpolate: the
       integer ns offset over the interval, both as doubles) and the arguments of its two
       per-time sines, (1 - r) theta and r theta: the divisions in vector lanes (IEEE
       division rounds the same in every lane). Lanes without an interval hold num 0,
       den 1, theta 0: r 0, both arguments 0. */
    static TFB_CLONES void tfb_ratio_block(const double* TFB_RESTRICT num,
                                           const double* TFB_RESTRICT den,
                                           const double* TFB_RESTRICT th,
                                           double* TFB_RESTRICT rr,
                                           double* TFB_RESTRICT sx) {
        int j;
        for (j = 0; j < TFB_BLOCK; j++) {
            double r = num[j] / den[j];
            rr[j] = r;
            sx[j] = (1.0 - r) * th[j];
            sx[TFB_BLOCK + j] = r * th[j];
        }
    }

    /* The SIMD kernels this CPU runs (x86-64: AVX2), checked once at import. */
    /* slerp's per-time sines in vector lanes: glibc's libmvec (_ZGVdN4v_sin, the AVX2
       variant of sin in the x86-64 vector function ABI; at most 4 ulp from the correctly
       rounded sine, where libm's scalar sin is within 1 ulp). Its address is found at
       import by ctypes (_libmvec_sin_address below) and handed over with tfb_vsin_set,
       so the extension neither links libmvec nor calls dlopen itself (whose glibc 2.34
       symbol version would lift the wheel's manylinux tag). Without it (other libc,
       other CPU), libm's sin is called per lane, bit for bit the scalar walk's. */
    static int tfb_vsin_ok = 0;
    #if defined(TFB_X86_64) && defined(__linux__)
    typedef __m256d (*tfb_vsin_fn)(__m256d);
    static tfb_vsin_fn tfb_vsin = NULL;
    static __attribute__((target("avx2"))) void tfb_sin_lanes_vec(const double* x, double* y) {
        int j;
        for (j = 0; j < 2 * TFB_BLOCK; j += 4)
            _mm256_storeu_pd(y + j, tfb_vsin(_mm256_loadu_pd(x + j)));
    }
    static void tfb_vsin_set(size_t address) { tfb_vsin = (tfb_vsin_fn)(uintptr_t)address; }
    #define TFB_SIN_LANES_VEC(x, y) (tfb_vsin_ok ? (tfb_sin_lanes_vec(x, y), 1) : 0)
    #else
    static void tfb_vsin_set(size_t address) { (void)address; }
    #define TFB_SIN_LANES_VEC(x, y) 0
    #endif

    /* The SIMD kernels this CPU runs (x86-64: AVX2, and libmvec's sin if found), checked
       once at import; returns whether the vector sine is used. */
    static int tfb_simd_init(void) {
    #if defined(TFB_X86_64)
        __builtin_cpu_init();
        tfb_avx2 = __builtin_cpu_supports("avx2") ? 1 : 0;
    #endif
    #if defined(TFB_X86_64) && defined(__linux__)
        /* libmvec's AVX2 variants also use FMA instructions */
        tfb_vsin_ok = tfb_avx2 && __builtin_cpu_supports("fma") && tfb_vsin != NULL;
    #endif
        return tfb_vsin_ok;
    }
    """
    int tfb_avx2
    int tfb_vsin_ok
    int tfb_simd_init() noexcept nogil
    void tfb_vsin_set(size_t address) noexcept nogil
    void tfb_ratio_block(const double* num, const double* den, const double* th,
                         double* rr, double* sx) noexcept nogil
    bint TFB_SIN_LANES_VEC(const double* x, double* y) noexcept nogil
    bint TFB_INTERP_RUN_AVX2(const double* a, const double* bq, double d, const double* rr,
                             const double* sy, int j0, int j1,
                             double (*st)[32]) noexcept nogil
    void tfb_compose_block(double (*acc)[32], const double (*st)[32]) noexcept nogil
    void tfb_full_block(const double (*src)[32], const double (*tgt)[32],
                        double (*out)[32]) noexcept nogil
    long tfb_fetch_add(long* p, long v) noexcept nogil
    bint tfb_cas(long* p, long expected, long desired) noexcept nogil
    void* tfb_xchg(void** p, void* v) noexcept nogil


cdef enum:
    _BLOCK = 32  # rows gathered and composed together (must equal TFB_BLOCK above)
    _CHUNK = 512  # rows a thread claims at a time (a multiple of _BLOCK)


def _libmvec_sin_address():
    """The address of glibc libmvec's ``_ZGVdN4v_sin`` (the x86-64 vector function ABI's
    AVX2 sine of 4 doubles), or 0 where there is none (another libc, another system).
    Found with :mod:`ctypes` (``dlopen``/``dlsym``), which keeps the library loaded."""
    import ctypes

    global _LIBMVEC
    try:
        _LIBMVEC = ctypes.CDLL("libmvec.so.1")
        return ctypes.cast(_LIBMVEC._ZGVdN4v_sin, ctypes.c_void_p).value or 0
    except (OSError, AttributeError):
        return 0


_LIBMVEC = None
tfb_vsin_set(<size_t>_libmvec_sin_address())
_BATCH_VECTOR_SIN = bool(tfb_simd_init())
"""True when :func:`_batch_lookup_vector` takes slerp's per-time sines from glibc's libmvec
(``_ZGVdN4v_sin``, AVX2): its rows then agree with ``lookup_transform`` to within a few
ulp of the sines (well inside the batch tolerance 1e-12), not bit for bit. False (no libmvec, no
AVX2): libm's ``sin``, rows bit-identical to the scalar lookup."""


def _batch_simd(bint enable):
    """Tests only: False makes :func:`batch_lookup` take its scalar, bit-exact loops
    everywhere (libm's ``sin``, no AVX2 kernels: what a CPU without AVX2 runs); True
    restores what the import-time checks found. Returns whether the vector sine is now
    used. Not thread-safe: no batch may be running."""
    global tfb_avx2, tfb_vsin_ok
    if enable:
        return bool(tfb_simd_init())
    tfb_avx2 = 0
    tfb_vsin_ok = 0
    return False


cdef struct _BLink:
    const int64_t* st
    const double* va
    Py_ssize_t head
    Py_ssize_t tail
    double sv[7]  # a static link's value
    bint is_static
    bint check_only  # gathered (must succeed) but not accumulated: tf2's early exit
    Py_ssize_t cur  # search cursor: the last index found (sorted times advance it)
    # The last interpolation interval [ci - 1, ci] and its slerp constants (exact reuse).
    Py_ssize_t ci
    int64_t ct0  # its two stamps
    int64_t ct1
    double cspan  # <double>(ct1 - ct0)
    bint zero_angle
    double theta
    double d
    double bq[4]


cdef enum:
    _K_SKIP = 0  # row already failed, or fails here
    _K_COPY = 1  # a stored sample exactly
    _K_INTERP = 2  # between samples idx and idx + 1


cdef void _bgather(_BLink* L, const int64_t* times, int m, signed char* good,
                   double st[7][_BLOCK], bint vector_sin) noexcept nogil:
    """``TimeCache::c_gather`` of one link for the ``m`` rows of a block (times != 0,
    single-parent link) into ``st`` (column c, row j); ``good[j] = 0`` where tf2's gather
    would fail or the row needs the scalar walk (span >= 2**53 ns).

    Three passes, so that the libm calls run back to back: (1) find each row's sample or
    interval (a cursor that advances over sorted times, else a bisection) and the
    interval's slerp constants — tf2 ``Quaternion::slerp`` / ``angleShortestPath``:
    ``theta = acos(|dot| / |a||b|)``, ``1 / sin(theta)``, the sign flip of b — which
    depend on the two samples only and are computed once per interval (held in ``L``
    across blocks); (2) ``sin((1 - r) theta)`` and ``sin(r theta)`` per row (libmvec's
    vector sin if ``vector_sin`` and ``_BATCH_VECTOR_SIN``, else libm's); (3) each row as
    ``TimeCache.c_gather`` / ``_slerp`` compute it (``TimeCache::interpolate``: linear
    translation, the ratio from integer ns), same expressions, same order: bit-identical
    given the same sines.
    """
    cdef signed char kind[_BLOCK]
    cdef Py_ssize_t idx[_BLOCK]
    cdef int slot[_BLOCK]
    cdef double rr[_BLOCK]
    cdef double num[_BLOCK]
    cdef double den[_BLOCK]
    cdef double th[_BLOCK]
    cdef double sx[2 * _BLOCK]
    cdef double sy[2 * _BLOCK]
    # per interval met in this block (at most one per row)
    cdef double sd[_BLOCK]
    cdef double sbq[_BLOCK][4]
    cdef bint szero[_BLOCK]
    cdef int nslots = 0, cur_slot = -1, j, j1, c, sl
    cdef Py_ssize_t head = L.head, tail = L.tail, i, cur
    cdef const int64_t* stp = L.st
    cdef const double* va = L.va
    cdef const double* a
    cdef const double* b
    cdef int64_t t, t0, span, newest
    cdef double r, s, dot, cc, d, q0, q1
    cdef bint single, any_sin = False
    if L.is_static:
        for c in range(7):
            for j in range(_BLOCK):
                st[c][j] = L.sv[c]
        return
    if tail == head:  # not planned (a link without data makes the plan fail)
        for j in range(m):
            good[j] = 0
        return
    newest = stp[tail - 1]
    single = tail - head == 1
    cur = L.cur
    # (1) locate; each row's ratio as num / den and its slerp angle (0: no sine), the
    # divisions and the sines' arguments then in lanes (tfb_ratio_block); lanes without
    # an interval: r = 0 / 1, angle 0 (they compute sin(0); outside runs their values
    # are overwritten or never read)
    for j in range(m, _BLOCK):
        num[j] = 0.0
        den[j] = 1.0
        th[j] = 0.0
    for j in range(m):
        num[j] = 0.0
        den[j] = 1.0
        th[j] = 0.0
        if not good[j]:
            kind[j] = _K_SKIP
            continue
        t = times[j]
        if L.ci > 0 and L.ct0 < t and t < L.ct1:
            # Strictly inside the last interval (most sorted times): the slow path below
            # would find i = ci, nothing to recompute; same ratio, same arguments.
            if cur_slot < 0:
                cur_slot = _bslot(L, nslots, szero, sd, sbq)
                nslots += 1
            kind[j] = _K_INTERP
            idx[j] = L.ci - 1
            slot[j] = cur_slot
            num[j] = <double>(t - L.ct0)  # r = num / den, as below
            den[j] = L.cspan
            if not L.zero_angle:
                th[j] = L.theta
                any_sin = True
            continue
        kind[j] = _K_SKIP
        if t == newest:
            kind[j] = _K_COPY
            idx[j] = tail - 1
            continue
        if single or t > newest:
            good[j] = 0
            continue
        # i = the first index with stp[i] >= t (bisect_left), from the cursor if it can
        i = cur
        if not (i > head and i < tail and stp[i - 1] < t and t <= stp[i]):
            if i > head and i + 1 < tail and stp[i] < t and t <= stp[i + 1]:
                i += 1
            else:
                i = _bisect_left(stp, t, head, tail)
        cur = i
        if stp[i] == t:
            kind[j] = _K_COPY
            idx[j] = i
            continue
        if i == head:
            good[j] = 0
            continue
        t0 = stp[i - 1]
        span = stp[i] - t0
        if span >= EXACT_SPAN:
            good[j] = 0
            continue
        if i != L.ci:
            # tf2 slerp's per-interval part (Quaternion.h slerp / angleShortestPath,
            # as _slerp): same expressions and order.
            a = &va[(i - 1) * 7]
            b = &va[i * 7]
            L.bq[0] = b[3]
            L.bq[1] = b[4]
            L.bq[2] = b[5]
            L.bq[3] = b[6]
            dot = a[3] * L.bq[0] + a[4] * L.bq[1] + a[5] * L.bq[2] + a[6] * L.bq[3]
            if dot < 0.0:
                dot = -dot
                L.bq[0] = -L.bq[0]
                L.bq[1] = -L.bq[1]
                L.bq[2] = -L.bq[2]
                L.bq[3] = -L.bq[3]
            cc = dot / sqrt(
                (a[3] * a[3] + a[4] * a[4] + a[5] * a[5] + a[6] * a[6])
                * (L.bq[0] * L.bq[0] + L.bq[1] * L.bq[1] + L.bq[2] * L.bq[2]
                   + L.bq[3] * L.bq[3])
            )
            L.zero_angle = cc >= 1.0
            if not L.zero_angle:
                L.theta = acos(cc)
                L.d = 1.0 / sin(L.theta)
            L.ci = i
            L.ct0 = t0
            L.ct1 = stp[i]
            L.cspan = <double>span
            cur_slot = -1
        if cur_slot < 0:
            cur_slot = _bslot(L, nslots, szero, sd, sbq)
            nslots += 1
        kind[j] = _K_INTERP
        idx[j] = i - 1
        slot[j] = cur_slot
        # r = (t - t0) / span (TimeCache::interpolate's ratio, as _slerp is given it)
        num[j] = <double>(t - t0)
        den[j] = <double>span
        if not L.zero_angle:
            # the arguments of tf2 slerp's per-time sines, (1 - r) theta and r theta
            th[j] = L.theta
            any_sin = True
    L.cur = cur
    tfb_ratio_block(num, den, th, rr, sx)
    # (2) sin((1 - r) theta) in lanes 0..31, sin(r theta) in 32..63 (tf2 slerp's two
    # per-time transcendental calls): libmvec's vector sin where available (rows within
    # a few ulp of the scalar walk's), else libm's sin per row (bit for bit)
    if any_sin and not (vector_sin and TFB_SIN_LANES_VEC(sx, sy)):
        memset(sy, 0, sizeof(sy))
        for j in range(m):
            if kind[j] == _K_INTERP and not szero[slot[j]]:
                sy[j] = sin(sx[j])
                sy[_BLOCK + j] = sin(sx[_BLOCK + j])
    # (3) the rows; a run of rows in one interval shares its samples and constants
    j = 0
    while j < m:
        if kind[j] == _K_INTERP and not szero[slot[j]]:
            j1 = j + 1
            while j1 < m and kind[j1] == _K_INTERP and idx[j1] == idx[j]:
                j1 += 1
            sl = slot[j]
            _binterp_run(&va[idx[j] * 7], sbq[sl], sd[sl], rr, sy, j, j1, st)
            j = j1
            continue
        if kind[j] == _K_COPY:
            a = &va[idx[j] * 7]
            st[0][j] = a[0]
            st[1][j] = a[1]
            st[2][j] = a[2]
            st[3][j] = a[3]
            st[4][j] = a[4]
            st[5][j] = a[5]
            st[6][j] = a[6]
        elif kind[j] == _K_INTERP:
            a = &va[idx[j] * 7]
            b = a + 7
            r = rr[j]
            s = 1.0 - r
            st[0][j] = s * a[0] + r * b[0]
            st[1][j] = s * a[1] + r * b[1]
            st[2][j] = s * a[2] + r * b[2]
            sl = slot[j]
            if szero[sl]:
                st[3][j] = a[3]
                st[4][j] = a[4]
                st[5][j] = a[5]
                st[6][j] = a[6]
            else:
                d = sd[sl]
                q0 = sy[j]
                q1 = sy[_BLOCK + j]
                st[3][j] = (a[3] * q0 + sbq[sl][0] * q1) * d
                st[4][j] = (a[4] * q0 + sbq[sl][1] * q1) * d
                st[5][j] = (a[5] * q0 + sbq[sl][2] * q1) * d
                st[6][j] = (a[6] * q0 + sbq[sl][3] * q1) * d
        j += 1


cdef inline int _bslot(const _BLink* L, int n, bint* szero, double* sd,
                       double sbq[][4]) noexcept nogil:
    """Slot ``n`` of a block's intervals := the link's cached slerp constants."""
    szero[n] = L.zero_angle
    sd[n] = L.d
    sbq[n][0] = L.bq[0]
    sbq[n][1] = L.bq[1]
    sbq[n][2] = L.bq[2]
    sbq[n][3] = L.bq[3]
    return n


cdef inline void _binterp_run(const double* a, const double* bq, double d,
                              const double* rr, const double* sy, int j0, int j1,
                              double st[7][_BLOCK]) noexcept nogil:
    """Rows ``j0 <= j < j1``, all between samples ``a`` and ``a + 7`` (non-zero slerp
    angle): ``TimeCache::interpolate`` (lerp of the origins) and tf2 slerp's last step
    ``(a sin((1 - r) theta) + b sin(r theta)) / sin(theta)``, as ``TimeCache.c_gather``
    and ``_slerp`` compute them (``bq`` is b with slerp's sign flip, ``d`` 1/sin); in
    AVX2 lanes when the CPU has them (``tfb_interp_run_avx2``, same expressions)."""
    cdef const double* b = a + 7
    cdef double a0 = a[0], a1 = a[1], a2 = a[2], a3 = a[3], a4 = a[4], a5 = a[5]
    cdef double a6 = a[6], b0 = b[0], b1 = b[1], b2 = b[2]
    cdef double c0 = bq[0], c1 = bq[1], c2 = bq[2], c3 = bq[3]
    cdef double r, s, q0, q1
    cdef int j
    if TFB_INTERP_RUN_AVX2(a, bq, d, rr, sy, j0, j1, st):
        return
    for j in range(j0, j1):
        r = rr[j]
        s = 1.0 - r
        st[0][j] = s * a0 + r * b0
        st[1][j] = s * a1 + r * b1
        st[2][j] = s * a2 + r * b2
        q0 = sy[j]
        q1 = sy[_BLOCK + j]
        st[3][j] = (a3 * q0 + c0 * q1) * d
        st[4][j] = (a4 * q0 + c1 * q1) * d
        st[5][j] = (a5 * q0 + c2 * q1) * d
        st[6][j] = (a6 * q0 + c3 * q1) * d


cdef enum:
    C_MAX_DEPTH_BATCH = 64  # longer chains take the scalar walk


cdef int _bplan_side(list caches, int frame, int stop, int early, _BLink* links,
                     int* n, int* reached, bint* early_hit) except -1:
    """The structure of one ``_climb`` (by each link's single parent): append its links
    to ``links``. Returns 0, or 1 when no row can take the fast path (a link with no
    data, several parents or NO_PARENT, or a loop)."""
    cdef object obj
    cdef int parent
    cdef int depth = 0
    cdef _BLink* L
    early_hit[0] = False
    while frame != stop:
        obj = _link(caches, frame)
        if obj is None:
            break
        if n[0] >= C_MAX_DEPTH_BATCH:
            return 1
        L = &links[n[0]]
        memset(L, 0, sizeof(_BLink))
        L.ci = -1
        L.cur = -1
        if isinstance(obj, StaticCache):
            L.is_static = True
            memcpy(L.sv, (<StaticCache>obj)._v, 7 * sizeof(double))
            parent = (<StaticCache>obj)._parent
        elif isinstance(obj, TimeCache):
            if (<TimeCache>obj)._pa != NULL or (<TimeCache>obj)._tail == (<TimeCache>obj)._head:
                return 1
            L.st = (<TimeCache>obj)._st
            L.va = (<TimeCache>obj)._va
            L.head = (<TimeCache>obj)._head
            L.tail = (<TimeCache>obj)._tail
            parent = (<TimeCache>obj)._parent
        else:
            return 1
        if parent == 0:
            return 1
        n[0] += 1
        if frame == early:
            L.check_only = True
            early_hit[0] = True
            reached[0] = frame
            return 0
        frame = parent
        depth += 1
        if depth > C_MAX_DEPTH:
            return 1
    reached[0] = frame
    return 0


cdef inline void _bidentity_block(double acc[7][_BLOCK]) noexcept nogil:
    cdef int j
    for j in range(_BLOCK):
        acc[0][j] = acc[1][j] = acc[2][j] = acc[3][j] = acc[4][j] = acc[5][j] = 0.0
        acc[6][j] = 1.0


cdef inline void _bchain(_BLink* links, int n, const int64_t* times, int m,
                         double acc[7][_BLOCK], double st[7][_BLOCK],
                         signed char* good, bint vector_sin) noexcept nogil:
    """One ``_climb`` for the ``m`` rows of a block, link by link: each link's samples
    (``_bgather``), then ``acc = link ∘ acc`` over the whole block
    (``tfb_compose_block``: ``_compose``'s expressions in its order, so each row is
    bit-for-bit the scalar climb; lanes no longer good, or beyond ``m``, compute
    garbage that is never read)."""
    cdef int k
    if n == 0 or links[0].check_only:
        _bidentity_block(acc)
    for k in range(n):
        if k == 0 and not links[0].check_only:
            _bgather(&links[0], times, m, good, acc, vector_sin)  # acc = the first link
            continue
        _bgather(&links[k], times, m, good, st, vector_sin)
        if not links[k].check_only:
            tfb_compose_block(acc, st)


cdef struct _BJob:
    # the plan and the rows of one call (the caller waits for a worker that took it)
    _BLink src[C_MAX_DEPTH_BATCH]
    _BLink tgt[C_MAX_DEPTH_BATCH]
    int ns
    int nt
    bint src_early
    bint tgt_early
    const int64_t* times
    const int64_t* order  # row r of ``times`` is row order[r] of out / ok; NULL: r itself
    Py_ssize_t n_rows
    double* out
    signed char* ok
    long next_chunk  # atomic: the next chunk of _CHUNK rows to claim
    bint vector_sin  # slerp's per-time sines from libmvec (if found), else libm
    Py_ssize_t answered_worker
    Py_ssize_t rows_worker


cdef inline int _bstore(_BJob* job, Py_ssize_t rb, int m, const signed char* good,
                        double block[7][_BLOCK]) noexcept nogil:
    """Write the good rows of a block (rows ``rb`` .. ``rb + m - 1`` of ``job.times``)
    to ``job.out`` (at ``job.order``'s rows when the times were sorted) and mark them
    answered; how many were written."""
    cdef int j, k, n = 0
    cdef Py_ssize_t row
    cdef double* o
    for j in range(m):
        if good[j]:
            row = rb + j if job.order == NULL else job.order[rb + j]
            o = &job.out[row * 7]
            for k in range(7):
                o[k] = block[k][j]
            job.ok[row] = 1
            n += 1
    return n


cdef Py_ssize_t _brows(_BJob* job, Py_ssize_t* rows) noexcept nogil:
    """The per-time loop of :func:`batch_lookup`: claims chunks of ``_CHUNK`` rows until
    none is left and walks each in blocks of ``_BLOCK`` (no GIL). Every chunk starts from
    the plan's links (fresh cursor and interval cache: the result does not depend on
    which thread took which chunk)."""
    cdef _BLink src_links[C_MAX_DEPTH_BATCH]
    cdef _BLink tgt_links[C_MAX_DEPTH_BATCH]
    cdef double acc_s[7][_BLOCK]
    cdef double acc_t[7][_BLOCK]
    cdef double st[7][_BLOCK]
    cdef double res[7][_BLOCK]
    cdef signed char good[_BLOCK]
    cdef Py_ssize_t r0, r1, rb, answered = 0, n_rows = job.n_rows
    cdef const int64_t* times = job.times
    cdef int m, j, ns = job.ns, nt = job.nt
    cdef bint src_early = job.src_early, tgt_early = job.tgt_early
    memset(st, 0, sizeof(st))
    memset(acc_t, 0, sizeof(acc_t))
    while True:
        r0 = <Py_ssize_t>tfb_fetch_add(&job.next_chunk, 1) * _CHUNK
        if r0 >= n_rows:
            break
        r1 = r0 + _CHUNK if n_rows - r0 > _CHUNK else n_rows
        rows[0] += r1 - r0
        memcpy(src_links, job.src, ns * sizeof(_BLink))
        memcpy(tgt_links, job.tgt, nt * sizeof(_BLink))
        rb = r0
        while rb < r1:
            m = <int>(r1 - rb) if r1 - rb < _BLOCK else _BLOCK
            for j in range(m):
                good[j] = times[rb + j] != 0
            _bchain(src_links, ns, times + rb, m, acc_s, st, good, job.vector_sin)
            if src_early:
                answered += _bstore(job, rb, m, good, acc_s)
            else:
                _bchain(tgt_links, nt, times + rb, m, acc_t, st, good, job.vector_sin)
                if tgt_early:
                    _bidentity_block(acc_s)  # _cwalk's TargetParentOfSource: source = I
                tfb_full_block(acc_s, acc_t, res)
                answered += _bstore(job, rb, m, good, res)
            rb += _BLOCK
    return answered


# The second thread: one per process, started by the first call that splits and then
# kept, asleep on ``_w_wake`` between calls (a thread woken from sleep is scheduled sooner
# than a new one, and nothing is created per call). A call hands its job over through
# the one-slot mailbox ``_w_slot`` (atomic exchange: exactly one of the worker and the
# caller takes a job back out). The caller waits (``_w_done``) only for a job the worker
# took; a job still in the slot when the caller has done every row is taken back, so a
# worker that did not get a core in time costs the caller nothing. Ended at interpreter
# exit (``_worker_stop``, registered with atexit), forgotten in a forked child.
cdef PyThread_type_lock _w_wake = NULL  # released once per job handed over
cdef PyThread_type_lock _w_done = NULL  # released once per job the worker took
cdef PyThread_type_lock _w_exited = NULL  # released by the worker as it ends
cdef void* _w_slot = NULL  # the job waiting for the worker (atomic exchange only)
cdef bint _w_quit = False  # set before the last wake: the worker ends
cdef bint _w_running = False  # a worker thread is started (GIL held when read or set)
cdef bint _w_busy = False  # a call is using the worker (GIL held when read or set)
cdef long _w_started = 0  # worker threads started by this process (tests)


cdef void _bworker(void* arg) noexcept nogil:
    """The worker's loop: sleep until woken, take the job in the slot (if the caller has
    not taken it back), claim its chunks alongside the caller, release ``_w_done``;
    end when woken with ``_w_quit`` set."""
    cdef _BJob* job
    cdef PyThread_type_lock wake = <PyThread_type_lock>arg
    while True:
        PyThread_acquire_lock(wake, WAIT_LOCK)
        if _w_quit:
            break
        job = <_BJob*>tfb_xchg(&_w_slot, NULL)
        if job == NULL:  # woken for a job its caller already took back
            continue
        job.answered_worker = _brows(job, &job.rows_worker)
        PyThread_release_lock(_w_done)  # last touch of the job: the caller may free it
    PyThread_release_lock(_w_exited)


cdef bint _worker_ready() noexcept:
    """Start the worker if it is not running; whether it is (GIL held)."""
    global _w_wake, _w_done, _w_exited, _w_running, _w_quit, _w_started
    if _w_running:
        return True
    _w_wake = PyThread_allocate_lock()
    _w_done = PyThread_allocate_lock()
    _w_exited = PyThread_allocate_lock()
    if _w_wake == NULL or _w_done == NULL or _w_exited == NULL:
        _worker_free_locks()
        return False
    PyThread_acquire_lock(_w_wake, WAIT_LOCK)
    PyThread_acquire_lock(_w_done, WAIT_LOCK)
    PyThread_acquire_lock(_w_exited, WAIT_LOCK)
    _w_quit = False
    if PyThread_start_new_thread(_bworker, _w_wake) == <unsigned long>-1:
        _worker_free_locks()
        return False
    _w_running = True
    _w_started += 1
    return True


cdef void _worker_free_locks() noexcept:
    global _w_wake, _w_done, _w_exited
    if _w_wake != NULL:
        PyThread_free_lock(_w_wake)
    if _w_done != NULL:
        PyThread_free_lock(_w_done)
    if _w_exited != NULL:
        PyThread_free_lock(_w_exited)
    _w_wake = _w_done = _w_exited = NULL


def _worker_stop(double timeout=5.0):
    """End the batched lookups' worker thread, if one is running, and wait for it
    (at most ``timeout`` seconds); registered with :mod:`atexit`. The next call that
    splits starts a new one. Returns whether no worker is left running. Not to be called
    while a batch is running (a call in progress keeps the worker: returns False)."""
    global _w_running, _w_quit
    cdef bint ended
    cdef long long us = <long long>(timeout * 1e6)
    if not _w_running:
        return True
    if _w_busy:
        return False
    _w_quit = True
    PyThread_release_lock(_w_wake)
    with nogil:
        ended = PyThread_acquire_lock_timed(_w_exited, us, 0) == PY_LOCK_ACQUIRED
    if not ended:  # the worker did not get a core in time: it ends when it does
        return False
    _w_running = False
    _worker_free_locks()
    return True


def _worker_forget():
    """In a forked child: the parent's worker thread does not exist here (its locks are
    left as they are, a few bytes); the next call that splits starts a new one."""
    global _w_running, _w_busy, _w_wake, _w_done, _w_exited, _w_slot
    _w_running = False
    _w_busy = False
    _w_wake = _w_done = _w_exited = NULL
    _w_slot = NULL


def _worker_threads_started():
    """How many worker threads this process has started (tests: one, however many
    calls split, until :func:`_worker_stop`)."""
    return _w_started


atexit.register(_worker_stop)
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_worker_forget)


cdef Py_ssize_t _bsplit(const _BLink* src, int ns, bint src_early, const _BLink* tgt,
                        int nt, bint tgt_early, const int64_t* times, const int64_t* order,
                        Py_ssize_t n_rows, double* out, signed char* ok,
                        bint vector_sin) except -1:
    """``_brows`` over all rows; from ``_SPLIT_ROWS`` rows on (several CPUs), the worker
    thread (started once, then woken per call) claims chunks too. The split is dynamic
    (chunks of ``_CHUNK`` rows claimed from a shared counter), and a job the worker has
    not taken when the rows are done is taken back, not waited for. A machine busy with
    other work can still make the split lose (the caller waits for a preempted worker's
    chunk): each split call is judged against the caller's own pace
    (:func:`_split_verdict`), and after a losing one the next calls run on one thread
    (1, 2, 4, ... up to 64 calls) before two are tried again."""
    global _split_skip, _w_busy
    cdef _BJob* job = <_BJob*>malloc(sizeof(_BJob))
    cdef Py_ssize_t answered, own_rows = 0
    cdef bint threaded = n_rows >= _SPLIT_ROWS and _NCPU >= 2 and not _w_busy
    cdef bint worker_ran = False
    cdef int64_t t0 = 0, t1 = 0
    if job == NULL:
        raise MemoryError()
    if threaded and _split_skip > 0:  # a recent split lost to one thread
        _split_skip -= 1
        threaded = False
    memcpy(job.src, src, ns * sizeof(_BLink))
    memcpy(job.tgt, tgt, nt * sizeof(_BLink))
    job.ns = ns
    job.nt = nt
    job.src_early = src_early
    job.tgt_early = tgt_early
    job.times = times
    job.order = order
    job.n_rows = n_rows
    job.out = out
    job.ok = ok
    job.next_chunk = 0
    job.vector_sin = vector_sin
    job.answered_worker = 0
    job.rows_worker = 0
    if threaded:
        t0 = perf_counter_ns()
        threaded = _worker_ready()
    if threaded:
        _w_busy = True
        tfb_xchg(&_w_slot, job)
        PyThread_release_lock(_w_wake)
    # From the hand-over to the wait nothing may raise: the worker may be using the job.
    # The caller keeps the GIL throughout (its own rows and the wait): the plan points
    # into the caches' arrays, which another Python thread's insert would regrow or
    # overwrite.
    answered = _brows(job, &own_rows)
    if threaded:
        t1 = perf_counter_ns()
        if tfb_xchg(&_w_slot, NULL) == NULL:  # the worker took the job: wait for it
            PyThread_acquire_lock(_w_done, WAIT_LOCK)
            worker_ran = True
        _w_busy = False
        if worker_ran:
            answered += job.answered_worker
        free(job)
        _split_verdict(perf_counter_ns() - t0, t1 - t0, own_rows, n_rows, worker_ran)
    else:
        free(job)
    return answered


def batch_lookup(CoreBase core, object target_frame, object source_frame,
                 const int64_t[::1] times, double[:, ::1] out, int64_t[::1] stamps,
                 signed char[::1] ok):
    """``lookupTransform(target_frame, source_frame, t)`` for every t of ``times``, into
    caller-owned arrays (the bit-exact compiled entry of the batched lookups).

    For each row r with ``ok[r] == 1`` on return, ``out[r]`` is the transform (tx, ty,
    tz, qx, qy, qz, qw) mapping source into target and ``stamps[r]`` the time used
    (the caller fills ``stamps`` with ``times``; only rows at time 0 change): what
    ``lookup_transform`` returns for ``times[r]``, bit for bit (libm's sines; see
    :func:`_batch_lookup_vector` for the vectorised ones). Rows left at 0 are
    those the single lookup would fail for (the caller asks it for the exception).
    Returns the number of rows answered, or -1 when a frame id is not a known,
    queryable id (then no row is answered: the single lookup raises tf2's
    InvalidArgument / Lookup exception). ``target_frame == source_frame`` is the
    caller's (identity) case and returns -1 too.

    The path is resolved once; each time is then gathered and accumulated along it in C
    in ``_walk``'s arithmetic order. ``times`` may come in any order: from 64
    rows on, times that are not non-decreasing are walked sorted (``_bsorted``; the
    kernel's cursor and per-interval constants pay off on sorted times) and each row is
    written back to its place (a row's value does not depend on the order). Rows that
    plan cannot take (time 0, a link with several parents, a span >= 2**53 ns, a row
    missing data) go through ``_walk`` itself. From 8192 rows on a machine with several
    CPUs, a worker thread (started once per process, asleep between calls) claims chunks
    of rows alongside the caller; the caller keeps the GIL from the plan to the last row
    (its own and the worker's), so no other thread writes the buffer meanwhile.
    """
    return _batch_lookup(core, target_frame, source_frame, times, out, stamps, ok, False)


def lookup_rows(CoreBase core, object target_frame, object source_frame,
                const int64_t[::1] times, double[:, ::1] out, int64_t[::1] stamps,
                signed char[::1] ok):
    """:func:`batch_lookup` with slerp's per-time sines from glibc's libmvec where
    ``_BATCH_VECTOR_SIN`` (AVX2 vector sine, a few ulp from libm's): rows then agree with
    ``lookup_transform`` to within 1e-12 (the batch tolerance; ~1e-14 in practice), bit
    for bit where a row has no per-time sine; elsewhere it is :func:`batch_lookup`. The
    entry :meth:`tfbus.core.BufferCore.lookup_transforms` uses (the pure-Python core's
    ``lookup_rows`` is its ``batch_lookup``: it has no vector sine)."""
    return _batch_lookup(core, target_frame, source_frame, times, out, stamps, ok, True)


cdef Py_ssize_t _batch_lookup(CoreBase core, object target_frame, object source_frame,
                              const int64_t[::1] times, double[:, ::1] out,
                              int64_t[::1] stamps, signed char[::1] ok,
                              bint vector_sin) except -2:
    """:func:`batch_lookup` (``vector_sin`` False) and :func:`_batch_lookup_vector`."""
    cdef Py_ssize_t n_rows = times.shape[0], r, answered = 0
    cdef _BLink src_links[C_MAX_DEPTH_BATCH]
    cdef _BLink tgt_links[C_MAX_DEPTH_BATCH]
    cdef int ns = 0, nt = 0, top = 0, frame = 0, where = 0, err
    cdef int target_id, source_id
    cdef bint src_early = False, tgt_early = False, planned
    cdef int64_t used
    cdef list caches = core._caches
    cdef const int64_t* row_times
    cdef const int64_t* order = NULL
    cdef const int64_t[::1] sorted_times
    cdef const int64_t[::1] sort_order
    if (out.shape[0] != n_rows or out.shape[1] != 7 or ok.shape[0] != n_rows
            or stamps.shape[0] != n_rows):
        raise ValueError("batch_lookup: out must be (N, 7), stamps and ok (N,) for N times")
    ok[:] = 0
    target_id = core._frame(target_frame)
    source_id = core._frame(source_frame)
    if target_id < 0 or source_id < 0 or target_id == source_id:
        return -1
    if n_rows:
        row_times = &times[0]
        if n_rows >= _SORT_ROWS and not _nondecreasing(row_times, n_rows):
            # The kernel's cursor and per-interval constants pay off on sorted times: walk
            # them sorted and write each row back to its place. Sorted before the plan is
            # made: numpy's sort lets other threads run (and insert) meanwhile.
            sorted_times, sort_order = _bsorted(times)
            row_times = &sorted_times[0]
            order = &sort_order[0]
    # From the plan to the end of the rows the GIL is held: the plan points into the
    # caches' arrays, which another thread's insert would regrow or overwrite.
    planned = _bplan_side(caches, source_id, 0, target_id, src_links, &ns, &top,
                          &src_early) == 0
    if planned and not src_early:
        planned = _bplan_side(caches, target_id, top, source_id, tgt_links, &nt, &frame,
                              &tgt_early) == 0
        if planned and not tgt_early and frame != top:
            planned = False  # disconnected: the scalar walk reports it
    if planned and n_rows:
        answered = _bsplit(src_links, ns, src_early, tgt_links, nt, tgt_early,
                           row_times, order, n_rows, &out[0, 0], &ok[0], vector_sin)
    if answered == n_rows:
        return answered
    for r in range(n_rows):
        if ok[r]:
            continue
        used = times[r]
        err = core._walk(target_id, source_id, &used, &out[r, 0], &where)
        if err == NO_ERROR:
            stamps[r] = used
            ok[r] = 1
            answered += 1
    return answered

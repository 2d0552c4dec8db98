"""Shared pieces of the fuzz tests: bounded, derandomized hypothesis settings and the
mutations of a valid payload a broken or hostile peer sends (bits flipped, cut short,
extended, absurd lengths spliced over or into it, runs swapped or repeated)."""

from __future__ import annotations

import random

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st


def fuzz(examples: int) -> settings:
    """Deterministic, bounded hypothesis settings (no example database, no deadline)."""
    return settings(derandomize=True, database=None, deadline=None,
                    max_examples=examples, suppress_health_check=list(HealthCheck))


ABSURD: tuple[bytes, ...] = (
    b"\xff\xff\xff\xff", b"\x7f\xff\xff\xff", b"\x00\x00\x00\x80", b"\x00\x00\x00\x00",
    b"\x01\x00\x00\x00",
    b"\xdd\xff\xff\xff\xff",  # msgpack array32 of 2**32 - 1 items
    b"\xdf\x7f\xff\xff\xff",  # map32 of 2**31 - 1 pairs
    b"\xdb\xff\xff\xff\xff",  # str32 of 4 GiB
    b"\xc6\xff\xff\xff\xff",  # bin32 of 4 GiB
    b"\xcf\xff\xff\xff\xff\xff\xff\xff\xff",  # uint64 max
    b"\xd3\x80\x00\x00\x00\x00\x00\x00\x00",  # int64 min
    b"\xcb\x7f\xf8\x00\x00\x00\x00\x00\x01",  # float64 NaN with a payload
    b"\xcb\x7f\xf0\x00\x00\x00\x00\x00\x00",  # float64 +inf
    b"\x00" * 8,
)
"""Lengths, counts and values a hostile or broken peer may put anywhere: CDR ``uint32``
lengths (both byte orders), msgpack container and string heads, extreme numbers."""


def mutate(valid: bytes, rng: random.Random) -> bytes:
    """``valid`` changed by 1 to 4 mutations drawn from ``rng``: flip a bit, cut, extend,
    splice an absurd length over the bytes at a place or insert one there, swap two runs,
    repeat a run."""
    out = bytearray(valid)
    for _ in range(rng.randint(1, 4)):
        n = len(out)
        op = rng.randrange(7)
        at = rng.randint(0, n)
        if op == 0 and n:
            out[at % n] ^= 1 << rng.randrange(8)
        elif op == 1:
            del out[at:]
        elif op == 2:
            out += rng.randbytes(rng.randint(1, 24))
        elif op == 3:
            value = rng.choice(ABSURD)
            out[at:at + len(value)] = value
        elif op == 4:
            out[at:at] = rng.choice(ABSURD)
        elif op == 5 and n >= 2:
            k = rng.randint(1, max(1, min(8, n // 2)))
            a, b = rng.randint(0, n - k), rng.randint(0, n - k)
            out[a:a + k], out[b:b + k] = out[b:b + k], out[a:a + k]
        elif op == 6 and n:
            k = rng.randint(1, min(16, n))
            a = rng.randint(0, n - k)
            out[at:at] = out[a:a + k]
    return bytes(out)


def mutants(valid: bytes) -> st.SearchStrategy[bytes]:
    """Hypothesis strategy of :func:`mutate` of ``valid``."""
    return st.randoms(use_true_random=False).map(lambda rng: mutate(valid, rng))

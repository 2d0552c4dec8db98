"""Two small msgpack readers the wire decoder runs *before* msgspec (sans I/O, no deps).

* :func:`read_head` reads the envelope's first three fields (``sender``, ``seq``,
  ``tag``) by hand, so that the body is never skipped over generically (msgspec skips
  an unknown value recursively: a payload nested 1 000 deep raised ``RecursionError``).
* :func:`check_depth` walks one msgpack value iteratively and refuses nesting deeper
  than a bound, so that a generic (``Any``) decode that follows cannot recurse far.

Byte layout from the msgpack specification (https://github.com/msgpack/msgpack/blob/
master/spec.md, "Formats"). Both raise :class:`~tfbus.errors.WireDecodeError` for bytes
that are not msgpack (truncated, reserved byte ``0xc1``) and
:class:`~tfbus.errors.WireLimitError` for nesting over the bound.
"""

from __future__ import annotations

import re
from typing import Final

from tfbus.errors import WireDecodeError, WireLimitError

__all__ = ["check_depth", "read_head"]

# type byte -> number of bytes of the whole item when it has a fixed size
_FIXED: Final[dict[int, int]] = {
    0xC0: 1, 0xC2: 1, 0xC3: 1,  # nil, false, true
    0xCA: 5, 0xCB: 9,  # float32, float64
    0xCC: 2, 0xCD: 3, 0xCE: 5, 0xCF: 9,  # uint8..64
    0xD0: 2, 0xD1: 3, 0xD2: 5, 0xD3: 9,  # int8..64
    0xD4: 3, 0xD5: 4, 0xD6: 6, 0xD7: 10, 0xD8: 18,  # fixext 1..16 (+ type byte)
}  # fmt: skip
# type byte -> (size of its big-endian length field, bytes after the payload's length)
_SIZED: Final[dict[int, tuple[int, int]]] = {
    0xC4: (1, 0), 0xC5: (2, 0), 0xC6: (4, 0),  # bin 8/16/32
    0xC7: (1, 1), 0xC8: (2, 1), 0xC9: (4, 1),  # ext 8/16/32 (+ type byte)
    0xD9: (1, 0), 0xDA: (2, 0), 0xDB: (4, 0),  # str 8/16/32
}  # fmt: skip
# type byte -> (size of its count field, items per counted entry)
_CONTAINERS: Final[dict[int, tuple[int, int]]] = {
    0xDC: (2, 1), 0xDD: (4, 1),  # array 16/32
    0xDE: (2, 2), 0xDF: (4, 2),  # map 16/32: key and value
}  # fmt: skip


# A run of one-byte items (fixints, nil, false, true): skipped in one regex step.
_ONE_BYTE_RUN: Final = re.compile(rb"[\x00-\x7f\xc0\xc2\xc3\xe0-\xff]+")


def _truncated() -> WireDecodeError:
    return WireDecodeError("truncated msgpack data")


def _read_int(data: bytes, pos: int) -> tuple[int, int]:
    """An integer at ``pos``: (value, position after it)."""
    if pos >= len(data):
        raise _truncated()
    b = data[pos]
    if b <= 0x7F:
        return b, pos + 1
    if b >= 0xE0:
        return b - 0x100, pos + 1
    if 0xCC <= b <= 0xD3:
        size = 1 << ((b - 0xCC) & 3)
        end = pos + 1 + size
        if end > len(data):
            raise _truncated()
        return int.from_bytes(data[pos + 1 : end], "big", signed=b >= 0xD0), end
    raise WireDecodeError(f"expected a msgpack integer at byte {pos}, found 0x{b:02x}")


def _read_str(data: bytes, pos: int) -> tuple[str, int]:
    """A string at ``pos``: (value, position after it)."""
    if pos >= len(data):
        raise _truncated()
    b = data[pos]
    if 0xA0 <= b <= 0xBF:
        start, length = pos + 1, b & 0x1F
    elif b in (0xD9, 0xDA, 0xDB):
        size = 1 << (b - 0xD9)
        start = pos + 1 + size
        length = int.from_bytes(data[pos + 1 : start], "big")
    else:
        raise WireDecodeError(f"expected a msgpack string at byte {pos}, found 0x{b:02x}")
    end = start + length
    if end > len(data):
        raise _truncated()
    try:
        return data[start:end].decode("utf-8"), end
    except UnicodeDecodeError as exc:
        raise WireDecodeError(f"invalid UTF-8 in a string at byte {pos}") from exc


def read_head(data: bytes, pos: int) -> tuple[int, int, str, int]:
    """Read ``[sender, seq, tag, ...`` at ``pos``: ``(sender, seq, tag, body_position)``.

    The envelope must be a msgpack array of exactly 4 items; the body is its last item
    and runs to the end of ``data``.

    Raises:
        WireDecodeError: not an array of 4, or a field of the wrong msgpack type.
    """
    if pos >= len(data):
        raise _truncated()
    b = data[pos]
    if b == 0x94:
        pos += 1
    elif b in (0xDC, 0xDD):
        size = 2 if b == 0xDC else 4
        if int.from_bytes(data[pos + 1 : pos + 1 + size], "big") != 4:
            raise WireDecodeError("the envelope must be an array of 4 items")
        pos += 1 + size
    else:
        raise WireDecodeError("the envelope must be an array of 4 items")
    sender, pos = _read_int(data, pos)
    seq, pos = _read_int(data, pos)
    tag, pos = _read_str(data, pos)
    return sender, seq, tag, pos


def check_depth(data: bytes, pos: int, max_depth: int) -> int:
    """Walk the msgpack value at ``pos`` without building it; return the position after it.

    Containers (arrays, maps) nested more than ``max_depth`` deep are refused before any
    decoder recurses into them. Iterative: the walk itself never recurses. Cost: one
    step per item, bounded by ``len(data)`` (every item takes at least one byte).

    Raises:
        WireLimitError: nesting deeper than ``max_depth``.
        WireDecodeError: truncated data or the reserved byte ``0xc1``.
    """
    n = len(data)
    stack: list[int] = []  # items still to read in each enclosing container
    left = 1  # items still to read at the current level
    while True:
        while left == 0:
            if not stack:
                return pos
            left = stack.pop()
        if pos >= n:
            raise _truncated()
        b = data[pos]
        if b <= 0x7F or b >= 0xE0 or b in (0xC0, 0xC2, 0xC3):  # one-byte items: a run
            match = _ONE_BYTE_RUN.match(data, pos)
            assert match is not None
            taken = min(match.end() - pos, left)
            pos += taken
            left -= taken
            continue
        left -= 1
        count = 0
        if b <= 0x8F:  # fixmap
            count = (b & 0x0F) * 2
            pos += 1
        elif b <= 0x9F:  # fixarray
            count = b & 0x0F
            pos += 1
        elif b <= 0xBF:  # fixstr
            pos += 1 + (b & 0x1F)
            continue
        elif b in _FIXED:
            pos += _FIXED[b]
            continue
        elif b in _SIZED:
            size, extra = _SIZED[b]
            start = pos + 1 + size
            if start > n:
                raise _truncated()
            pos = start + extra + int.from_bytes(data[pos + 1 : start], "big")
            continue
        elif b in _CONTAINERS:
            size, per = _CONTAINERS[b]
            start = pos + 1 + size
            if start > n:
                raise _truncated()
            count = per * int.from_bytes(data[pos + 1 : start], "big")
            pos = start
        else:  # 0xc1: never used
            raise WireDecodeError(f"invalid msgpack byte 0x{b:02x} at byte {pos}")
        if count:
            stack.append(left)
            left = count
            if len(stack) > max_depth:
                raise WireLimitError(
                    f"msgpack values nested deeper than {max_depth} levels at byte {pos}"
                )

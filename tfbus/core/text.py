"""tf2's texts for :mod:`tfbus.core`: the messages of rejected transforms and invalid
query arguments, and the ``allFramesAsString`` / ``allFramesAsYAML`` dumps.

Each text is tf2 0.7.6's (``tf2/src/buffer_core.cpp``) character for character where tf2
defines it; YAML quoting is added only for ids YAML would misread.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Final, NamedTuple

from tfbus.core._select import INVALID_ARGUMENT
from tfbus.errors import InvalidArgumentException, LookupException, TransformException
from tfbus.time import Time

__all__ = [
    "FrameInfo",
    "Tf7",
    "bad_frame_exception",
    "frames_as_dot",
    "frames_as_string",
    "frames_as_yaml",
    "invalid_transform_exception",
]

Tf7 = tuple[float, float, float, float, float, float, float]
"""A transform as ``(tx, ty, tz, qx, qy, qz, qw)``: metres; quaternion (x, y, z, w)."""

_FIELDS: Final = (
    "transform.translation.x",
    "transform.translation.y",
    "transform.translation.z",
    "transform.rotation.x",
    "transform.rotation.y",
    "transform.rotation.z",
    "transform.rotation.w",
)


class FrameInfo(NamedTuple):
    """One linked frame, as :meth:`BufferCore.frame_info` reports it."""

    child: str
    parent: str
    """``NO_PARENT`` for a link emptied by ``clear()``."""
    authority: str
    is_static: bool
    samples: int
    oldest_ns: int
    """Oldest stamp held, nanoseconds (0 when empty, and for a static link)."""
    newest_ns: int
    """Newest stamp held, nanoseconds (0 when empty, and for a static link)."""


_YAML_PLAIN_FIRST: Final = frozenset("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ_")
_YAML_PLAIN_REST: Final = _YAML_PLAIN_FIRST | frozenset("0123456789./-")
# YAML 1.1 / 1.2 booleans and null, compared in lower case
_YAML_RESERVED: Final = frozenset(["y", "n", "yes", "no", "true", "false", "on", "off", "null"])


def _yaml_plain(frame_id: str) -> bool:
    """Whether ``frame_id`` reads back as the same string written plain in YAML (1.1 and
    1.2): a letter or ``_`` first, then letters, digits, ``_ . / -``, and not a boolean or
    null word."""
    return (
        bool(frame_id)
        and frame_id[0] in _YAML_PLAIN_FIRST
        and all(c in _YAML_PLAIN_REST for c in frame_id)
        and frame_id.lower() not in _YAML_RESERVED
    )


def _yaml_quoted(text: str) -> str:
    """``text`` as a YAML quoted scalar: single quotes (``'`` doubled), as tf2 writes
    parents, unless it holds a character single quotes cannot carry (control characters,
    line breaks, non-printables): then double quotes with escapes."""
    if text.isprintable():
        return "'" + text.replace("'", "''") + "'"
    out = []
    for c in text:
        if c == '"' or c == "\\":
            out.append("\\" + c)
        elif c.isprintable():
            out.append(c)
        else:
            code = ord(c)
            if code < 0x100:
                out.append(f"\\x{code:02x}")
            elif code < 0x10000:
                out.append(f"\\u{code:04x}")
            else:
                out.append(f"\\U{code:08x}")
    return '"' + "".join(out) + '"'


def _yaml_key(frame_id: str) -> str:
    """A frame id as a YAML mapping key: plain as tf2 writes it when YAML reads it back
    unchanged, else quoted."""
    return frame_id if _yaml_plain(frame_id) else _yaml_quoted(frame_id)


def frames_as_string(infos: Iterable[FrameInfo]) -> str:
    """tf2 ``allFramesAsString``: ``Frame X exists with parent Y.`` per linked frame."""
    return "".join(f"Frame {info.child} exists with parent {info.parent}.\n" for info in infos)


def frames_as_yaml(infos: Iterable[FrameInfo], current_time: Time | None = None) -> str:
    """tf2 ``allFramesAsYAML`` over ``infos`` (see
    :meth:`tfbus.core.BufferCore.all_frames_as_yaml`); ``[]`` when no link holds data."""
    out: list[str] = []
    for child, parent, authority, _static, samples, oldest, newest in infos:
        if not samples:  # a dynamic link emptied by clear(): tf2 lists only data
            continue
        rate = samples / max((newest - oldest) / 1e9, 0.0001)
        out.append(f"{_yaml_key(child)}: \n")
        out.append(f"  parent: {_yaml_quoted(parent)}\n")
        out.append(f"  broadcaster: {_yaml_quoted(authority)}\n")
        out.append(f"  rate: {rate:.3f}\n")
        out.append(f"  most_recent_transform: {newest / 1e9:.3f}\n")
        out.append(f"  oldest_transform: {oldest / 1e9:.3f}\n")
        if current_time is not None and current_time.ns > 0:
            out.append(f"  transform_delay: {(current_time.ns - newest) / 1e9:.3f}\n")
        out.append(f"  buffer_length: {(newest - oldest) / 1e9:.3f}\n")
    return "".join(out) if out else "[]"


def invalid_transform_exception(
    parent: str, child: str, values: Tf7, authority: str
) -> InvalidArgumentException:
    """InvalidArgumentException listing every problem of a transform in tf2's order
    (``BufferCore::setTransformImpl``) plus tfbus's TF_INF_INPUT."""
    codes: list[str] = []
    problems: list[str] = []
    if child == parent:
        codes.append("TF_SELF_TRANSFORM")
        problems.append(f"header.frame_id and child_frame_id are the same ({child!r})")
    if not child:
        codes.append("TF_NO_CHILD_FRAME_ID")
        problems.append("child_frame_id is empty")
    if not parent:
        codes.append("TF_NO_FRAME_ID")
        problems.append("header.frame_id is empty")
    nans = [f"{name} = nan" for name, v in zip(_FIELDS, values, strict=True) if math.isnan(v)]
    if nans:
        codes.append("TF_NAN_INPUT")
        problems.extend(nans)
    infs = [
        f"{name} = {v}" for name, v in zip(_FIELDS[:3], values[:3], strict=True) if math.isinf(v)
    ]
    if infs:
        codes.append("TF_INF_INPUT")
        problems.extend(infs)
    qx, qy, qz, qw = values[3:]
    # tf2's order (setTransformImpl: w² + x² + y² + z²): it decides cases at the limit.
    norm2 = qw * qw + qx * qx + qy * qy + qz * qz
    if not abs(norm2 - 1.0) < 0.01:
        codes.append("TF_DENORMALIZED_QUATERNION")
        problems.append(
            f"transform.rotation = ({qx}, {qy}, {qz}, {qw}) has squared norm {norm2}, "
            "not within 0.01 of 1"
        )
    return InvalidArgumentException(
        f"Invalid transform for child_frame_id {child!r} from authority {authority!r}: "
        + "; ".join(problems),
        codes=tuple(codes),
    )


def bad_frame_exception(label: str, frame: object, code: int) -> TransformException:
    """tf2 ``validateFrameId``'s exception for a query argument ``label`` (e.g.
    ``lookupTransform argument target_frame``)."""
    if not isinstance(frame, str):
        return InvalidArgumentException(
            f"Invalid argument {frame!r} passed to {label}: frame ids are strings"
        )
    if code == INVALID_ARGUMENT:
        if not frame:
            return InvalidArgumentException(
                f"Invalid argument passed to {label} in tf2 frame_ids cannot be empty"
            )
        return InvalidArgumentException(
            f'Invalid argument "{frame}" passed to {label} in tf2 frame_ids '
            "cannot start with a '/' like: "
        )
    return LookupException(f'"{frame}" passed to {label} does not exist. ')


def frames_as_dot(
    frame_names: Iterable[str], infos: Iterable[FrameInfo], current_time_s: float = 0.0
) -> str:
    """tf2 0.7.6 ``BufferCore::_allFramesAsDot`` (view_frames' graph) over every known
    frame id (registration order) and the links' :class:`FrameInfo`: one edge
    ``"parent" -> "child"`` per link holding data, labelled with its broadcaster, rate
    (Hz, samples / span, span at least 0.1 ms), newest stamp (and, when
    ``current_time_s`` > 0, its age) and buffer length (seconds, 3 decimals); then a
    legend node pointing at each root (a frame with no link: only when
    ``current_time_s`` > 0; a link emptied by ``clear()``: always).
    ``'digraph G {\n"no tf data recieved"}'`` (tf2's spelling) for an empty buffer."""
    names = list(frame_names)
    by_child = {info.child: info for info in infos}
    out = ["digraph G {\n"]
    if not names:
        out.append('"no tf data recieved"')
    for name in names:
        info = by_child.get(name)
        if info is None or not info.samples:
            continue
        newest, oldest = info.newest_ns / 1e9, info.oldest_ns / 1e9
        rate = info.samples / max(newest - oldest, 0.0001)
        age = f"( {current_time_s - newest:.3f} sec old)" if current_time_s > 0 else ""
        out.append(
            f'"{info.parent}" -> "{name}"[label="Broadcaster: {info.authority}\\n'
            f"Average rate: {rate:.3f} Hz\\nMost recent transform: {newest:.3f} {age}\\n"
            f'Buffer length: {(info.newest_ns - info.oldest_ns) / 1e9:.3f} sec\\n"];\n'
        )
    legend = ' subgraph cluster_legend { style=bold; color=black; label ="view_frames Result";\n'
    recorded = f'"Recorded at time: {current_time_s:.3f}"[ shape=plaintext ] ;\n '
    for name in names:
        info = by_child.get(name)
        if info is None and current_time_s > 0:
            out.append(f'edge [style=invis];\n{legend}{recorded}}}->"{name}";\n')
        elif info is not None and info.parent == "NO_PARENT":
            stamp = recorded if current_time_s > 0 else ""
            out.append(f'edge [style=invis];\n{legend}{stamp}}}->"{name}";\n')
    out.append("}")
    return "".join(out)

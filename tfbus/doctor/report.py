"""What ``tfbus doctor`` found: :class:`Level`, :class:`Finding`, :class:`Report` and the
JSON Schema of :meth:`Report.to_json` (:data:`REPORT_SCHEMA`, reproduced in
``docs/doctor.md``).

Times are integer nanoseconds of receive time (bag time for a recording, the listener's
clock live); delays are float seconds.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import Enum
from typing import Any, Final

__all__ = ["REPORT_SCHEMA", "SCHEMA_VERSION", "BroadcasterDelay", "Finding", "Level", "Report"]

SCHEMA_VERSION: Final = 1
"""The ``schema_version`` of :meth:`Report.to_json` (raised when a field changes meaning)."""


class Level(str, Enum):
    """How bad a finding is: ``error`` (lookups fail or return wrong data), ``warning``
    (they will under some timing or at some time), ``info`` (worth knowing)."""

    ERROR = "error"
    WARNING = "warning"
    INFO = "info"

    @property
    def rank(self) -> int:
        """2 for error, 1 for warning, 0 for info: ``a.rank >= b.rank`` is "at least as bad"."""
        return {"error": 2, "warning": 1, "info": 0}[self.value]

    def __str__(self) -> str:
        return str(self.value)

    @classmethod
    def parse(cls, value: str) -> Level:
        """The level named ``value`` (``"error"``, ``"warning"``, ``"info"``).

        Raises:
            ValueError: any other value, naming it.
        """
        try:
            return cls(value)
        except ValueError:
            raise ValueError(f"level must be one of error, warning, info, got {value!r}") from None


@dataclass(frozen=True)
class Finding:
    """One problem of a tf tree.

    Attributes:
        check: the check that found it (a key of :data:`tfbus.doctor.CHECKS`).
        level: how bad it is.
        message: one line saying what is wrong.
        frames: the frame ids involved (child frames first).
        senders: the broadcasters (authorities) involved.
        start_ns, end_ns: the receive-time span (ns) over which it was seen, None when it
            is a property of the whole tree (a loop seen once has ``start_ns == end_ns``).
        advice: one line saying what to do about it.
        counts: numbers behind the finding (messages per sender, gaps, seconds...).
        lookups: ``(target_frame, source_frame)`` pairs whose ``lookup_transform`` fails
            because of it (disconnected trees).
        reference: where the rule comes from (tf2 file/function, REP, FAQ).
    """

    check: str
    level: Level
    message: str
    frames: tuple[str, ...] = ()
    senders: tuple[str, ...] = ()
    start_ns: int | None = None
    end_ns: int | None = None
    advice: str = ""
    counts: Mapping[str, int | float] = field(default_factory=dict)
    lookups: tuple[tuple[str, str], ...] = ()
    reference: str = ""

    def to_dict(self) -> dict[str, Any]:
        """The finding as JSON values (the ``findings`` items of :data:`REPORT_SCHEMA`)."""
        return {
            "check": self.check,
            "level": self.level.value,
            "message": self.message,
            "frames": list(self.frames),
            "senders": list(self.senders),
            "start_ns": self.start_ns,
            "end_ns": self.end_ns,
            "advice": self.advice,
            "counts": dict(self.counts),
            "lookups": [list(p) for p in self.lookups],
            "reference": self.reference,
        }


@dataclass(frozen=True)
class BroadcasterDelay:
    """Receive time minus header stamp of one broadcaster's dynamic transforms: the
    clock offset plus the latency (seconds), over a bounded sample of them.

    Attributes:
        sender: the broadcaster (authority).
        transforms: dynamic transforms received from it.
        median: median delay, seconds (negative: its stamps are ahead of the receiver).
        spread: 90th minus 10th percentile of the delays, seconds.
        samples: delays the median and spread were taken over (at most
            :attr:`tfbus.doctor.Thresholds.delay_samples`, spread over the whole run).
    """

    sender: str
    transforms: int
    median: float
    spread: float
    samples: int

    def to_dict(self) -> dict[str, Any]:
        """As JSON values (the ``broadcasters`` items of :data:`REPORT_SCHEMA`)."""
        return {"sender": self.sender, "transforms": self.transforms, "median_delay_s":
                self.median, "spread_s": self.spread, "samples": self.samples}


@dataclass(frozen=True)
class Report:
    """Everything :func:`tfbus.doctor.diagnose` found.

    Attributes:
        source: what was diagnosed (a bag path, a bus spec).
        findings: most severe first, then by check and frames.
        messages: tf messages read (both topics).
        transforms: transforms read.
        frames: frame ids seen, parents included (as ``tfbus bag-info`` and tf2's
            ``BufferCore::getAllFrameNames`` count them), over the tracked links.
        links: child frames seen, each with its parent (at most
            :attr:`~tfbus.doctor.Thresholds.max_frames` tracked).
        start_ns, end_ns: receive times of the first and the last message (None: none).
        sim_time: the stamps are simulated time (far from the receive clock): delays are
            measured against the newest stamp, so clock offsets cannot be told.
        broadcasters: each broadcaster's delays.
    """

    source: str
    findings: tuple[Finding, ...]
    messages: int = 0
    transforms: int = 0
    frames: int = 0
    links: int = 0
    start_ns: int | None = None
    end_ns: int | None = None
    sim_time: bool = False
    broadcasters: tuple[BroadcasterDelay, ...] = ()

    def at_least(self, level: Level | str) -> tuple[Finding, ...]:
        """The findings at ``level`` or worse (``"warning"``: warnings and errors).

        Raises:
            ValueError: an unknown level name.
        """
        floor = level if isinstance(level, Level) else Level.parse(level)
        return tuple(f for f in self.findings if f.level.rank >= floor.rank)

    def by_check(self, check: str) -> tuple[Finding, ...]:
        """The findings of one check."""
        return tuple(f for f in self.findings if f.check == check)

    def to_dict(self) -> dict[str, Any]:
        """The report as JSON values, valid against :data:`REPORT_SCHEMA`."""
        return {
            "schema_version": SCHEMA_VERSION,
            "source": self.source,
            "messages": self.messages,
            "transforms": self.transforms,
            "frames": self.frames,
            "links": self.links,
            "start_ns": self.start_ns,
            "end_ns": self.end_ns,
            "sim_time": self.sim_time,
            "counts": {lv.value: sum(f.level is lv for f in self.findings) for lv in Level},
            "findings": [f.to_dict() for f in self.findings],
            "broadcasters": [b.to_dict() for b in self.broadcasters],
        }

    def to_json(self, indent: int | None = 2) -> str:
        """:meth:`to_dict` as JSON text (valid against :data:`REPORT_SCHEMA`; non-ASCII
        characters and control characters escaped, so the text is safe on a terminal)."""
        return json.dumps(self.to_dict(), indent=indent, ensure_ascii=True)


_NS = {"type": ["integer", "null"], "description": "receive time, ns"}
_COUNTS = {
    "type": "object",
    "additionalProperties": {"type": "number"},
}

REPORT_SCHEMA: Final[dict[str, Any]] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "$id": "urn:tfbus:doctor-report:1",
    "title": "tfbus doctor report",
    "type": "object",
    "required": ["schema_version", "source", "messages", "transforms", "frames", "links",
                 "start_ns", "end_ns", "sim_time", "counts", "findings", "broadcasters"],
    "additionalProperties": False,
    "properties": {
        "schema_version": {"const": SCHEMA_VERSION},
        "source": {"type": "string", "description": "the bag path or the bus spec"},
        "messages": {"type": "integer", "minimum": 0},
        "transforms": {"type": "integer", "minimum": 0},
        "frames": {"type": "integer", "minimum": 0,
                   "description": "frame ids seen, parents included"},
        "links": {"type": "integer", "minimum": 0,
                  "description": "child frames seen (each with its parent)"},
        "start_ns": _NS,
        "end_ns": _NS,
        "sim_time": {"type": "boolean"},
        "counts": {
            "type": "object",
            "required": ["error", "warning", "info"],
            "additionalProperties": False,
            "properties": {lv: {"type": "integer", "minimum": 0}
                           for lv in ("error", "warning", "info")},
        },
        "findings": {
            "type": "array",
            "items": {
                "type": "object",
                "required": ["check", "level", "message", "frames", "senders", "start_ns",
                             "end_ns", "advice", "counts", "lookups", "reference"],
                "additionalProperties": False,
                "properties": {
                    "check": {"type": "string"},
                    "level": {"enum": ["error", "warning", "info"]},
                    "message": {"type": "string"},
                    "frames": {"type": "array", "items": {"type": "string"}},
                    "senders": {"type": "array", "items": {"type": "string"}},
                    "start_ns": _NS,
                    "end_ns": _NS,
                    "advice": {"type": "string"},
                    "counts": _COUNTS,
                    "lookups": {
                        "type": "array",
                        "items": {"type": "array", "items": {"type": "string"},
                                  "minItems": 2, "maxItems": 2},
                    },
                    "reference": {"type": "string"},
                },
            },
        },
        "broadcasters": {
            "type": "array",
            "items": {
                "type": "object",
                "required": ["sender", "transforms", "median_delay_s", "spread_s", "samples"],
                "additionalProperties": False,
                "properties": {
                    "sender": {"type": "string"},
                    "transforms": {"type": "integer", "minimum": 0},
                    "median_delay_s": {"type": "number"},
                    "spread_s": {"type": "number", "minimum": 0},
                    "samples": {"type": "integer", "minimum": 0},
                },
            },
        },
    },
}
"""JSON Schema (draft 2020-12) of :meth:`Report.to_json`, reproduced in ``docs/doctor.md``."""

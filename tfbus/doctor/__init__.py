"""``tfbus doctor``: what is wrong with a tf tree, in a recording or live on a bus.

::

    from tfbus.doctor import diagnose
    report = diagnose("run.bag")                     # one streaming pass, bounded memory
    for f in report.findings:                        # most severe first
        print(f.level, f.check, f.frames, f.senders, f.message, f.advice)
    print(report.to_json())                          # REPORT_SCHEMA (docs/doctor.md)

Live: a :class:`DoctorSink` fed by a :class:`~tfbus.listener.TransformListener`, then
``doctor.report(now=clock.now())``.

The checks (:data:`CHECKS`: name, rule, reference): several authorities for one frame,
static and dynamic for one frame, parent changes, loops, REP 105's order and the
base_footprint convention, frame ids starting with '/', stopped frames, gaps, rate
drops, repeated and out-of-order stamps, clock offset and latency per broadcaster,
disconnected trees, and a damaged recording. Their numbers are :class:`Thresholds`.

The package, one job per module:

* :mod:`~tfbus.doctor.report`: :class:`Level`, :class:`Finding`, :class:`Report`,
  :data:`REPORT_SCHEMA`;
* :mod:`~tfbus.doctor.checks`: :class:`Doctor` (the one-pass state), :class:`Thresholds`,
  :data:`CHECKS`;
* :mod:`~tfbus.doctor.sources`: :func:`diagnose` (recordings), :class:`DoctorSink`
  (live buses).
"""

from __future__ import annotations

from tfbus.doctor.checks import CHECKS, PLACEHOLDER_AUTHORITIES, Check, Doctor, Thresholds
from tfbus.doctor.report import (
    REPORT_SCHEMA,
    SCHEMA_VERSION,
    BroadcasterDelay,
    Finding,
    Level,
    Report,
)
from tfbus.doctor.sources import DoctorSink, diagnose

__all__ = [
    "CHECKS",
    "PLACEHOLDER_AUTHORITIES",
    "REPORT_SCHEMA",
    "SCHEMA_VERSION",
    "BroadcasterDelay",
    "Check",
    "Doctor",
    "DoctorSink",
    "Finding",
    "Level",
    "Report",
    "Thresholds",
    "diagnose",
]

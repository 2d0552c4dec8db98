"""Differential-conformance harness: replay tf2 0.7.6 recordings against tfbus.

The corpus (``tests/data/public.jsonl.gz``, see ``tests/data/README.md``) holds 400 cases;
each is a list of ops run in order on one fresh ``BufferCore``, with what the real tf2 did.
This module loads the cases, runs every op on a tfbus ``BufferCore`` to produce an
``actual`` value with the same JSON shape as the op's ``expect``, and compares the two
with the corpus rules:

* **level 1** (required): outcome kind, error class, stamps, frame ids, translations
  within 1e-9 m, rotations within 1e-9 rad up to sign, quaternion norms within 1e-9,
  non-finite where tf2 was non-finite;
* **level 2**: level 1 plus exact exception messages, ``can_transform`` debug messages
  and the ``TF_*`` codes of refused ``set``\\ s.

The one intended deviation from tf2: tf2 stores translations containing ±Inf (and then
returns NaN); tfbus rejects them with ``InvalidArgumentException`` whose codes contain
``TF_INF_INPUT``. Such a ``set`` is checked to be rejected that way; the later ops of the
case that depend on it (a non-finite expected value, or a frame that only the rejected
sample would have linked) are classified ``DEVIATION`` and reported, and for them tfbus is
only required never to return a non-finite value.
"""

from __future__ import annotations

import enum
import gzip
import json
import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any, Final, TypeAlias

from tfbus import (
    Duration,
    Header,
    InvalidArgumentException,
    Quaternion,
    Time,
    Transform,
    TransformException,
    TransformStamped,
    Vector3,
)

__all__ = [
    "ANGLE_TOL",
    "CORPUS",
    "DEVIATIONS",
    "NORM_TOL",
    "T_TOL",
    "Case",
    "CaseReport",
    "Op",
    "OpReport",
    "Status",
    "compare",
    "decode_float",
    "deviating_ops",
    "load_cases",
    "make_transform",
    "rotation_angle",
    "run_case",
]

DEVIATIONS: Final = "tf2_deviations"
"""The name under which ``test_level1`` records the ops of its case that differ from tf2 by
design, ``(case id, [line per op])``, in its report's ``user_properties`` (which reach the
main process from pytest-xdist's workers, where ``config.stash`` would not);
``conftest.pytest_terminal_summary`` sums them up in one line at the end of a run and lists
them with ``-v``."""

CORPUS: Final = Path(__file__).parent / "data" / "public.jsonl.gz"

T_TOL: Final = 1e-9
"""Absolute tolerance per translation component (metres)."""
ANGLE_TOL: Final = 1e-9
"""Tolerance on the rotation angle between actual and expected, sign-insensitive (rad)."""
NORM_TOL: Final = 1e-9
"""Tolerance on ``| |q_actual| - |q_expected| |`` (tf2 never normalises quaternions)."""

INF_CODE: Final = "TF_INF_INPUT"
"""The code tfbus adds for ±Inf input (the intended deviation from tf2)."""

Case: TypeAlias = dict[str, Any]
"""One JSON line of the corpus."""
Op: TypeAlias = dict[str, Any]
"""One op of a case: ``{"op": "set" | "lookup" | ..., ..., "expect": ...}``."""
Actual: TypeAlias = Any
"""What tfbus did, in the shape of the op's ``expect`` (see ``run_op``)."""

_SPECIAL: Final[dict[str, float]] = {
    "NaN": math.nan,
    "Infinity": math.inf,
    "-Infinity": -math.inf,
}


def decode_float(value: float | int | str) -> float:
    """A corpus number: a JSON number or one of ``"NaN"``, ``"Infinity"``, ``"-Infinity"``."""
    if isinstance(value, str):
        return _SPECIAL[value]
    return float(value)


def _floats(values: Sequence[float | int | str]) -> list[float]:
    return [decode_float(v) for v in values]


@cache
def load_cases(path: Path = CORPUS) -> tuple[Case, ...]:
    """All cases of a ``.jsonl`` or ``.jsonl.gz`` corpus, in file order (parsed once)."""
    opener: Callable[..., Any] = gzip.open if path.suffix == ".gz" else open
    with opener(path, "rt", encoding="utf-8") as f:
        return tuple(json.loads(line) for line in f if line.strip())


# --------------------------------------------------------------------------- comparison


def _both_non_finite(actual: float, expected: float) -> bool | None:
    """None when both values are finite; otherwise whether both are non-finite.

    Where tf2 produced NaN or ±Inf any non-finite value is accepted (which one comes out
    of ``inf * 0`` arithmetic depends on the formula); a finite expected value needs a
    finite actual one.
    """
    if math.isfinite(actual) and math.isfinite(expected):
        return None
    return not math.isfinite(actual) and not math.isfinite(expected)


def _vectors_close(actual: Sequence[float], expected: Sequence[float], tol: float) -> bool:
    if len(actual) != len(expected):
        return False
    for a, e in zip(actual, expected, strict=True):
        special = _both_non_finite(a, e)
        if special is None:
            if abs(a - e) > tol:
                return False
        elif not special:
            return False
    return True


def _norm(q: Sequence[float]) -> float:
    return math.sqrt(math.fsum(x * x for x in q))


def rotation_angle(a: Sequence[float], e: Sequence[float]) -> float:
    """The angle (rad) of the rotation between two quaternions, insensitive to sign.

    Both are normalised, then ``4·atan2(|a - s·e|, |a + s·e|)`` with ``s = sign(a·e)``,
    which resolves angles far below the ~1e-8 rad limit of ``2·acos(|a·e|)``.
    """
    na, ne = _norm(a), _norm(e)
    ua = [x / na for x in a]
    ue = [x / ne for x in e]
    s = 1.0 if math.fsum(x * y for x, y in zip(ua, ue, strict=True)) >= 0.0 else -1.0
    diff = math.sqrt(math.fsum((x - s * y) ** 2 for x, y in zip(ua, ue, strict=True)))
    summ = math.sqrt(math.fsum((x + s * y) ** 2 for x, y in zip(ua, ue, strict=True)))
    return 4.0 * math.atan2(diff, summ)


def _quaternions_close(actual: Sequence[float], expected: Sequence[float]) -> bool:
    if len(actual) != 4 or len(expected) != 4:
        return False
    if not all(math.isfinite(x) for x in (*actual, *expected)):
        # Non-finite results: component-wise, up to a global sign.
        return _vectors_close(actual, expected, T_TOL) or _vectors_close(
            actual, [-x for x in expected], T_TOL
        )
    na, ne = _norm(actual), _norm(expected)
    if abs(na - ne) > NORM_TOL:
        return False
    if na == 0.0 or ne == 0.0:
        return na == ne
    return rotation_angle(actual, expected) <= ANGLE_TOL


def rolling_class(error: str, message: str) -> str:
    """The class ROS 2's tf2 raises where tf2 0.7.6 raised ``error`` with ``message``.

    tf2 0.7.6 has one ``ExtrapolationException``; rolling (``tf2/src/cache.cpp``) raises a
    subclass chosen by the same ``createExtrapolationException1/2/3`` whose text the
    corpus recorded from the real tf2: ``... into the future`` (2) is
    ``ForwardExtrapolationException``, ``... into the past`` (3)
    ``BackwardExtrapolationException``, ``... at time T, but only time ...`` (1) and an
    empty link ``NoDataForExtrapolationException``. Other classes are unchanged.
    """
    if error != "ExtrapolationException":
        return error
    detail = message.split(", when looking up transform", 1)[0]
    if "s into the future." in detail:
        return "ForwardExtrapolationException"
    if "s into the past." in detail:
        return "BackwardExtrapolationException"
    return "NoDataForExtrapolationException"


def _compare_error(expected: dict[str, Any], actual: Actual, strict: bool) -> str | None:
    if not isinstance(actual, dict) or "error" not in actual:
        return f"expected {expected['error']}: {expected['message']!r}, got a result {actual!r}"
    if actual["error"] != rolling_class(expected["error"], expected["message"]):
        return (
            f"expected {expected['error']}: {expected['message']!r}\n"
            f"     got {actual['error']}: {actual.get('message')!r}"
        )
    if strict and actual.get("message") != expected["message"]:
        return (
            f"{expected['error']} message differs:\n"
            f"  expected {expected['message']!r}\n  actual   {actual.get('message')!r}"
        )
    return None


def _compare_transform(expected: dict[str, Any], actual: Actual, strict: bool) -> str | None:
    if "error" in expected:
        return _compare_error(expected, actual, strict)
    if "error" in actual:
        return f"expected a result, got {actual['error']}: {actual.get('message')!r}"
    if actual["stamp_ns"] != expected["stamp_ns"]:
        return f"stamp_ns {actual['stamp_ns']} != expected {expected['stamp_ns']}"
    for key in ("frame_id", "child_frame_id"):
        if actual[key] != expected[key]:
            return f"{key} {actual[key]!r} != expected {expected[key]!r}"
    at, et = _floats(actual["t"]), _floats(expected["t"])
    if not _vectors_close(at, et, T_TOL):
        return f"translation {at} != expected {et}"
    aq, eq = _floats(actual["q"]), _floats(expected["q"])
    if not _quaternions_close(aq, eq):
        detail = ""
        if all(math.isfinite(x) for x in (*aq, *eq)) and _norm(aq) and _norm(eq):
            detail = (
                f" (angle {rotation_angle(aq, eq):.3g} rad, norms {_norm(aq)!r} vs {_norm(eq)!r})"
            )
        return f"rotation {aq} != expected {eq}{detail}"
    return None


def compare(op: Op, actual: Actual, *, strict: bool) -> str | None:
    """Compare tfbus's ``actual`` with tf2's ``op["expect"]``: None if they agree, else why.

    ``strict=False`` is level 1, ``strict=True`` level 2 (also messages and ``TF_*`` codes).
    """
    kind = op["op"]
    expected: Any = op.get("expect")
    if kind == "clear":
        return None
    if kind == "set":
        if actual["accepted"] != expected["accepted"]:
            why = actual.get("message") or actual.get("codes") or ""
            return (
                f"set accepted={actual['accepted']} (tfbus: {why!r}), expected "
                f"{expected['accepted']} (tf2 codes {expected.get('codes')})"
            )
        if strict and not expected["accepted"]:
            codes = actual.get("codes")
            if codes is not None and _is_inf_translation_set(op):
                codes = [c for c in codes if c != INF_CODE]  # the intended deviation
            if codes is not None and list(codes) != list(expected["codes"]):
                return f"set codes {list(codes)} != expected {expected['codes']}"
        return None
    if kind in ("lookup", "lookup_full"):
        return _compare_transform(expected, actual, strict)
    if kind == "latest_common_time":
        if "error" in expected:
            return _compare_error(expected, actual, strict)
        if "error" in actual:
            return f"expected a stamp, got {actual['error']}: {actual.get('message')!r}"
        if actual["stamp_ns"] != expected["stamp_ns"]:
            return f"stamp_ns {actual['stamp_ns']} != expected {expected['stamp_ns']}"
        return None
    if kind in ("can_transform", "can_transform_full"):
        if actual["result"] != expected:
            return (
                f"can_transform {actual['result']} (tfbus says {actual['message']!r}), "
                f"expected {expected} (tf2 says {op.get('expect_message', '')!r})"
            )
        if strict and actual["message"] != op.get("expect_message", ""):
            return (
                "can_transform message differs:\n"
                f"  expected {op.get('expect_message', '')!r}\n  actual   {actual['message']!r}"
            )
        return None
    raise ValueError(f"unknown op {kind!r}")


# --------------------------------------------------------------------------- running ops


def make_transform(op: Op) -> TransformStamped:
    """The ``TransformStamped`` of a ``set`` op."""
    tx, ty, tz = _floats(op["t"])
    qx, qy, qz, qw = _floats(op["q"])
    return TransformStamped(
        header=Header(stamp=Time.from_ns(op["stamp_ns"]), frame_id=op["parent"]),
        child_frame_id=op["child"],
        transform=Transform(translation=Vector3(tx, ty, tz), rotation=Quaternion(qx, qy, qz, qw)),
    )


def _error(exc: BaseException) -> dict[str, Any]:
    if isinstance(exc, TransformException):
        return {"error": type(exc).__name__, "message": str(exc)}
    # Anything else is a tfbus bug; its name can never match a tf2 class name.
    return {"error": f"<crash {type(exc).__name__}>", "message": str(exc)}


def _transform_result(ts: TransformStamped) -> dict[str, Any]:
    return {
        "t": list(ts.transform.translation),
        "q": list(ts.transform.rotation),
        "stamp_ns": ts.header.stamp.ns,
        "frame_id": ts.header.frame_id,
        "child_frame_id": ts.child_frame_id,
    }


def _run_set(core: Any, op: Op, detailed: bool) -> dict[str, Any]:
    ts = make_transform(op)
    authority = op.get("authority", "")
    static = bool(op.get("static"))
    insert = getattr(core, "insert_transform", None) if detailed else None
    try:
        if insert is not None:
            # tfbus's BufferCore.insert_transform -> SetResult tells *why* it refused.
            outcome = insert(ts, authority, static)
            if outcome.name == "STORED":
                return {"accepted": True}
            return {"accepted": False, "codes": [outcome.value]}
        setter = core.set_transform_static if static else core.set_transform
        stored = setter(ts, authority)
    except InvalidArgumentException as exc:
        return {"accepted": False, "codes": list(getattr(exc, "codes", ())), "message": str(exc)}
    except Exception as exc:
        return {"accepted": None, **_error(exc)}
    if stored is True:
        return {"accepted": True}
    if stored is False:
        refusal = getattr(core, "last_refusal", None)
        return {"accepted": False, "codes": None if refusal is None else [refusal]}
    return {"accepted": None, "error": "<crash>", "message": f"set returned {stored!r}"}


def _can_transform(call: Callable[..., Any]) -> dict[str, Any]:
    """Both forms of ``can_transform``: the plain bool and the debug tuple must agree."""
    try:
        plain = call()
        result, message = call(return_debug_tuple=True)
    except Exception as exc:
        return {"result": None, "message": f"raised {_error(exc)}"}
    if plain is not result:
        return {"result": None, "message": f"bool {plain!r} but debug tuple {result!r}"}
    return {"result": result, "message": message}


def run_op(core: Any, op: Op, *, detailed: bool = False) -> Actual:
    """Execute one op on ``core``; return what happened in the shape of ``op["expect"]``.

    ``set`` gives ``{"accepted": bool, "codes": [...] | None}``: codes from the
    ``InvalidArgumentException``; for a cache refusal, None unless ``detailed``, which
    calls ``core.insert_transform`` (returns a ``SetResult`` naming TF_OLD_DATA or
    TF_REPEATED_DATA) instead of the bool-returning ``set_transform(_static)``.
    ``can_transform*`` gives ``{"result": bool, "message": str}``; ``clear`` None.
    """
    kind = op["op"]
    if kind == "set":
        return _run_set(core, op, detailed)
    if kind == "clear":
        core.clear()
        return None
    if kind == "can_transform":
        target, source, time = op["target"], op["source"], Time.from_ns(op["time_ns"])
        return _can_transform(lambda **kw: core.can_transform(target, source, time, **kw))
    if kind == "can_transform_full":
        args = (
            op["target"],
            Time.from_ns(op["target_time_ns"]),
            op["source"],
            Time.from_ns(op["source_time_ns"]),
            op["fixed"],
        )
        return _can_transform(lambda **kw: core.can_transform_full(*args, **kw))
    try:
        if kind == "lookup":
            return _transform_result(
                core.lookup_transform(op["target"], op["source"], Time.from_ns(op["time_ns"]))
            )
        if kind == "lookup_full":
            return _transform_result(
                core.lookup_transform_full(
                    op["target"],
                    Time.from_ns(op["target_time_ns"]),
                    op["source"],
                    Time.from_ns(op["source_time_ns"]),
                    op["fixed"],
                )
            )
        if kind == "latest_common_time":
            return {"stamp_ns": core.get_latest_common_time(op["target"], op["source"]).ns}
    except Exception as exc:
        return _error(exc)
    raise ValueError(f"unknown op {kind!r}")


# --------------------------------------------------------------------------- the deviation


def _is_inf_translation_set(op: Op) -> bool:
    """A ``set`` whose translation holds ±Inf: tfbus must reject it (TF_INF_INPUT)."""
    return op["op"] == "set" and any(math.isinf(x) for x in _floats(op["t"]))


def _strip_one_slash(frame: str) -> str:
    return frame[1:] if frame.startswith("/") else frame


def _expects_non_finite(op: Op) -> bool:
    expected = op.get("expect")
    if not isinstance(expected, dict):
        return False
    values = [*expected.get("t", ()), *expected.get("q", ())]
    return any(not math.isfinite(x) for x in _floats(values))


def _query_frames(op: Op) -> set[str]:
    return {op[k] for k in ("target", "source", "fixed") if k in op}


def deviating_ops(case: Case) -> dict[int, str]:
    """Indices of the ops of ``case`` touched by the intended ±Inf deviation, with why.

    * a ``set`` that tf2 accepted with ±Inf in its translation (tfbus must reject it);
    * a later op whose expected value is non-finite, or that names a frame linked only
      by such a rejected sample (its child, and any frame later hung below it).

    Decided from the corpus alone, so the list is the same whatever the core does.
    """
    found: dict[int, str] = {}
    tainted: set[str] = set()
    for index, op in enumerate(case["ops"]):
        if _is_inf_translation_set(op) and op["expect"]["accepted"]:
            child = _strip_one_slash(op["child"])
            tainted.add(child)
            found[index] = f"tf2 stores ±Inf translation {op['t']} of {child!r}; tfbus rejects"
            continue
        if op["op"] == "set":
            if op["expect"]["accepted"] and _strip_one_slash(op["parent"]) in tainted:
                tainted.add(_strip_one_slash(op["child"]))
            continue
        if not tainted:
            continue
        if _expects_non_finite(op):
            found[index] = "tf2 returns non-finite values through the ±Inf sample"
        elif _query_frames(op) & tainted:
            found[index] = f"names {sorted(_query_frames(op) & tainted)}, linked only by ±Inf"
    return found


def _non_finite_in(actual: Actual) -> bool:
    if not isinstance(actual, dict):
        return False
    values = [*actual.get("t", ()), *actual.get("q", ())]
    return any(not math.isfinite(float(x)) for x in values)


def _check_deviation(op: Op, actual: Actual) -> str | None:
    """The check for an op in ``deviating_ops``."""
    if _is_inf_translation_set(op):
        if actual.get("accepted") is not False or actual.get("codes") is None:
            return f"tfbus must reject a ±Inf translation with InvalidArgumentException: {actual}"
        if INF_CODE not in actual["codes"]:
            return f"rejected, but codes {actual['codes']} lack {INF_CODE}"
        return None
    if _non_finite_in(actual):
        return f"tfbus returned non-finite values: {actual}"
    return None


# --------------------------------------------------------------------------- reports


class Status(enum.Enum):
    PASS = "pass"
    FAIL = "fail"
    DEVIATION = "deviation"
    """Differs from tf2 because of the intended ±Inf deviation, and checked as such."""


@dataclass(frozen=True, slots=True)
class OpReport:
    index: int
    op: Op
    actual: Actual
    level1: str | None
    """None if level 1 agrees, else the reason."""
    level2: str | None
    """None if level 2 agrees, else the reason."""
    deviation: str | None
    """Why the op is touched by the ±Inf deviation, or None."""

    def status(self, *, strict: bool) -> Status:
        if self.deviation is not None:
            # For a deviation op, level1/level2 hold the result of the deviation check.
            return Status.DEVIATION if self.level1 is None else Status.FAIL
        why = self.level2 if strict else self.level1
        return Status.PASS if why is None else Status.FAIL

    def describe(self, *, strict: bool) -> str:
        args = {k: v for k, v in self.op.items() if k not in ("expect", "expect_message", "op")}
        text = ", ".join(f"{k}={v!r}" for k, v in args.items())
        if len(text) > 300:
            text = text[:300] + "…"
        why = self.level2 if strict else self.level1
        if self.deviation is not None and why is None:
            why = self.deviation
        return f"op {self.index} {self.op['op']}({text}):\n    {why}"


@dataclass(frozen=True, slots=True)
class CaseReport:
    case: Case
    ops: tuple[OpReport, ...]

    def with_status(self, status: Status, *, strict: bool) -> list[OpReport]:
        return [r for r in self.ops if r.status(strict=strict) is status]

    def failures(self, *, strict: bool) -> list[OpReport]:
        return self.with_status(Status.FAIL, strict=strict)

    def deviations(self) -> list[OpReport]:
        return self.with_status(Status.DEVIATION, strict=False)

    def summary(self, *, strict: bool, limit: int = 12) -> str:
        failures = self.failures(strict=strict)
        head = (
            f"{self.case['id']} ({self.case['category']}): {len(failures)} of "
            f"{len(self.ops)} ops fail at level {2 if strict else 1}\n"
            f"  {self.case['description']}\n"
        )
        body = "\n".join("  " + f.describe(strict=strict) for f in failures[:limit])
        more = f"\n  … and {len(failures) - limit} more" if len(failures) > limit else ""
        return head + body + more


def run_case(
    case: Case,
    core_factory: Callable[[Duration], Any] | None = None,
    *,
    detailed: bool = False,
) -> CaseReport:
    """Run every op of ``case`` on a fresh core and compare each at levels 1 and 2.

    ``detailed=False`` drives the public bool API (``set_transform``); ``detailed=True``
    uses ``insert_transform`` so that level 2 also sees the code of cache refusals.
    """
    if core_factory is None:
        from tfbus.core import BufferCore

        core_factory = BufferCore
    core = core_factory(Duration.from_ns(case["cache_time_ns"]))
    deviations = deviating_ops(case)
    reports: list[OpReport] = []
    for index, op in enumerate(case["ops"]):
        actual = run_op(core, op, detailed=detailed)
        deviation = deviations.get(index)
        if deviation is not None:
            level1 = level2 = _check_deviation(op, actual)
        else:
            level1 = compare(op, actual, strict=False)
            level2 = level1 if level1 is not None else compare(op, actual, strict=True)
        reports.append(OpReport(index, op, actual, level1, level2, deviation))
    return CaseReport(case, tuple(reports))


def iter_ops(cases: Sequence[Case]) -> Iterator[tuple[Case, int, Op]]:
    """Every op of every case, with its case and index."""
    for case in cases:
        for index, op in enumerate(case["ops"]):
            yield case, index, op

"""``CoreBase._plain_transform``, the broadcaster's quick test of a transform before it
is published, and ``CoreBase._message_of_one``, that test and the message of the one
transform it accepts, on both twins (compiled and pure): the same answer bit for bit, True only
for what ``set_transform`` accepts (tf2 ``BufferCore::setTransformImpl``'s checks), and
for a transform of the message classes with float values exactly what it accepts,
except two forms it leaves to the core: a translation whose sum overflows, and a
'/'-prefixed id (which the core strips, as tf2 does)."""

from __future__ import annotations

import itertools
import math
from types import ModuleType

import pytest

from tfbus import Header, Quaternion, TFMessage, Time, Transform, TransformStamped, Vector3
from tfbus.core import BufferCore, _pycore
from tfbus.errors import InvalidArgumentException

_ccore = pytest.importorskip("tfbus.core._ccore", reason="the compiled core is not built here")

CORES: dict[str, ModuleType] = {"compiled": _ccore, "pure": _pycore}


def ts(
    parent: str = "map",
    child: str = "base",
    t: tuple[float, float, float] = (1.0, 2.0, 3.0),
    q: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0),
) -> TransformStamped:
    return TransformStamped(
        Header(Time(5), parent), child, Transform(Vector3(*t), Quaternion(*q))
    )


def accepted(transform: object) -> bool:
    """Whether a fresh core's set_transform stores it (False: it raises)."""
    try:
        return BufferCore().set_transform(transform)  # type: ignore[arg-type]
    except (InvalidArgumentException, TypeError):
        return False


def plain(twin: str, transform: object) -> bool:
    answer = CORES[twin].CoreBase._plain_transform(transform)
    assert type(answer) is bool
    return answer


# w for a squared norm just inside and just outside tf2's 0.01 of 1, both sides.
_NEAR = [math.sqrt(1.01), math.nextafter(math.sqrt(1.01), 0.0), math.sqrt(0.99),
         math.nextafter(math.sqrt(0.99), 2.0), 1.0 + 0.00499, 1.0 + 0.00501,
         1.004987562112089, 1.0049875621120892]
_VALUES = [0.0, -0.0, 1e308, -1e308, math.inf, -math.inf, math.nan, 5e-324]


def float_cases() -> list[TransformStamped]:
    cases = [ts(q=(0.0, 0.0, 0.0, w)) for w in _NEAR]
    cases += [ts(q=(0.0, 0.0, w, 0.0)) for w in _NEAR]
    cases += [ts(q=(math.sqrt(0.5), 0.0, 0.0, w)) for w in (math.sqrt(0.5), 0.7, 0.72)]
    cases += [ts(t=(a, b, 0.0)) for a, b in itertools.product(_VALUES, repeat=2)]
    cases += [ts(q=(0.0, 0.0, 0.0, v)) for v in _VALUES]
    cases += [ts(parent=p, child=c) for p, c in itertools.product(
        ["map", "", "/map", "base", "m"], ["base", "", "/base", "map", "m"])]
    return cases


@pytest.mark.parametrize("twin", sorted(CORES))
def test_the_quick_test_is_exactly_what_set_transform_accepts_for_float_transforms(
    twin: str,
) -> None:
    cases = float_cases()
    answers = [plain(twin, case) for case in cases]
    verdicts = [accepted(case) for case in cases]
    assert all(v for a, v in zip(answers, verdicts, strict=True) if a)  # True: stored, always
    left = [
        math.isinf(sum(c.transform.translation))
        or c.header.frame_id.startswith("/")
        or c.child_frame_id.startswith("/")
        for c in cases
    ]
    undecided = [c for c, a, v in zip(cases, answers, verdicts, strict=True) if a != v]
    assert undecided == [c for c, lf, v in zip(cases, left, verdicts, strict=True) if lf and v]
    # 1e308 + 1e308 and its negative; map -> /base, /map -> base, /map -> /base,
    # /map -> m, m -> /base: stored by the core, left to it by the quick test.
    assert len(undecided) == 7
    assert (sum(answers), len(answers)) == (38, 116)  # both verdicts, many times over
    # The last w below and the first above tf2's limit (w² - 1 = 0.009999999999999787,
    # then 0.010000000000000231): accepted, refused, by both twins and by the core.
    assert plain(twin, ts(q=(0.0, 0.0, 0.0, 1.004987562112089)))
    assert not plain(twin, ts(q=(0.0, 0.0, 0.0, 1.0049875621120892)))
    assert not accepted(ts(q=(0.0, 0.0, 0.0, 1.0049875621120892)))


def test_both_twins_answer_alike() -> None:
    odd: list[object] = [
        None,
        "map",
        (1, 2, 3),
        ts()._replace(transform=Transform(Vector3(1, 2, 3), Quaternion(0, 0, 0, 1))),
        ts()._replace(child_frame_id=b"base"),
        ts()._replace(header=Header(5, "map")),  # type: ignore[arg-type]
        ts()._replace(transform=tuple.__new__(Transform, ([1.0, 2.0, 3.0], Quaternion()))),
        tuple.__new__(TransformStamped, (Header(Time(5), "map"), "base")),  # too short
        ts()._replace(transform=tuple.__new__(Transform, (Vector3(),))),
        ts()._replace(transform=Transform(tuple.__new__(Vector3, (1.0, 2.0)), Quaternion())),
        ts()._replace(transform=Transform(Vector3(), tuple.__new__(Quaternion, (0.0, 1.0)))),
        ts()._replace(header=tuple.__new__(Header, (Time(5),))),
    ]

    class Sub(str):
        pass

    odd.append(ts(parent=Sub("map")))
    for case in [*odd, *float_cases()]:
        assert plain("compiled", case) == plain("pure", case), case
    # None of the odd forms is decided by the quick test (the broadcaster asks the core).
    assert not any(plain("compiled", case) for case in odd)


def test_the_message_of_one_is_the_tfmessage_of_what_the_quick_test_accepts() -> None:
    cases: list[object] = [*float_cases(), None, "map", (1, 2, 3),
                           ts()._replace(header=Header(5, "map"))]  # type: ignore[arg-type]
    made = 0
    for twin in sorted(CORES):
        for case in cases:
            message = CORES[twin].CoreBase._message_of_one(case)
            if not plain(twin, case):
                assert message is None, (twin, case)
                continue
            made += 1
            assert type(message) is TFMessage
            assert message == TFMessage((case,))  # type: ignore[arg-type]
            assert type(message.transforms) is tuple and message.transforms[0] is case
            assert message.transforms == (case,) and len(message) == 1
    assert made == 2 * 38  # the accepted float transforms of each twin

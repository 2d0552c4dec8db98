"""Velocity lookups (``BufferCore.lookup_velocity``, ``lookup_velocity_full``,
``Buffer.lookup_velocity_async``): tf2's numbers, checked against Debian's C++ libtf
``tf::Transformer::lookupTwist`` (``peers/debian/tf_velocity_ref.cpp``, built here with g++
against libtf-dev) on random moving 3-D trees; the documented non-physical example;
``method="origin"`` against finite differences of lookups; bad input."""

from __future__ import annotations

import math
import random
import subprocess
from functools import partial
from pathlib import Path

import pytest
from peer_install import require

from tfbus import (
    Buffer,
    BufferCore,
    Duration,
    Header,
    InvalidArgumentException,
    ManualClock,
    Quaternion,
    Time,
    TimeoutException,
    Transform,
    TransformException,
    TransformStamped,
    Vector3,
    VelocityStamped,
)

HERE = Path(__file__).resolve().parents[1]  # tests/: its cpp/ and data/
SEC = 1_000_000_000


def _ts(
    parent: str, child: str, ns: int, t: tuple[float, ...], q: tuple[float, ...]
) -> TransformStamped:
    return TransformStamped(Header(Time.from_ns(ns), parent), child,
                            Transform(Vector3(*t), Quaternion(*q)))


def _yaw(a: float) -> tuple[float, float, float, float]:
    return (0.0, 0.0, math.sin(a / 2), math.cos(a / 2))


def _moving_body(core: BufferCore) -> None:
    """``body`` moves +x at 2 m/s in ``world`` while yawing at 1 rad/s, sampled at 100 Hz."""
    for i in range(0, 301):
        t = i / 100
        core.set_transform(_ts("world", "body", i * 10_000_000, (2 * t, 0, 0), _yaw(t)))


# ------------------------------------------------------------------ known numbers


def test_rotating_frame_tf2_answer_is_not_physical() -> None:
    core = BufferCore(100.0)
    _moving_body(core)
    v = core.lookup_velocity("body", "world", Time.from_sec(0.5), 0.1)
    assert isinstance(v, VelocityStamped)
    assert v.header == Header(Time.from_ns(SEC // 2), "world")
    assert (v.body_frame_id, v.reference_frame_id) == ("body", "world")
    lin, ang = v.velocity
    # tf2: R(yaw) (2, 0, 0) + p x ω with p = (1, 0, 0), ω = (0, 0, 1)
    assert lin == pytest.approx((2 * math.cos(0.5), 2 * math.sin(0.5) - 1.0, 0.0), abs=1e-9)
    assert (round(lin.x, 3), round(lin.y, 3)) == (1.755, -0.041)
    assert ang == pytest.approx((0.0, 0.0, 1.0), abs=1e-9)


def test_rotating_frame_origin_method_is_physical() -> None:
    core = BufferCore(100.0)
    _moving_body(core)
    v = core.lookup_velocity("body", "world", Time.from_sec(0.5), 0.1, method="origin")
    assert v.velocity.linear == pytest.approx((2.0, 0.0, 0.0), abs=1e-9)
    assert v.velocity.angular == pytest.approx((0.0, 0.0, 1.0), abs=1e-9)
    # expressed in the body's own axes at t = 0.5: the world +x rotated by -0.5 rad
    b = core.lookup_velocity_full("body", "world", "body", (0, 0, 0), "body",
                                  Time.from_sec(0.5), 0.1, method="origin")
    assert b.header.frame_id == "body"
    expected = (2 * math.cos(0.5), -2 * math.sin(0.5), 0.0)
    assert b.velocity.linear == pytest.approx(expected, abs=1e-9)
    # a point 1 m ahead of the body (body +x): v + ω x r, r = R(0.5) (1, 0, 0)
    p = core.lookup_velocity_full("body", "world", "world", (1, 0, 0), "body",
                                  Time.from_sec(0.5), 0.1, method="origin")
    assert p.velocity.linear == pytest.approx((2 - math.sin(0.5), math.cos(0.5), 0.0), abs=1e-9)


def test_time_zero_is_latest_common_time_and_window_clamps() -> None:
    core = BufferCore(100.0)
    _moving_body(core)
    v = core.lookup_velocity("body", "world", Time(0), 0.2)
    # latest = 3 s: window [2.8, 3.0], stamp start + interval/2 (ROS 2)
    assert v.header.stamp == Time.from_ns(2_900_000_000)
    assert v.velocity.angular.z == pytest.approx(1.0, abs=1e-9)


def test_static_tree_gives_zero() -> None:
    core = BufferCore()
    core.set_transform_static(_ts("a", "b", 0, (1, 2, 3), _yaw(0.3)))
    v = core.lookup_velocity("b", "a", Time(0), 0.1)
    assert tuple(v.velocity.linear) == (0.0, 0.0, 0.0)
    assert tuple(v.velocity.angular) == (0.0, 0.0, 0.0)


# ------------------------------------------------------------------ finite differences


Row = tuple[str, str, int, tuple[float, ...], tuple[float, ...], bool]


def _random_tree(rng: random.Random, core: BufferCore, frames: int = 6,
                 samples: int = 40, step_ns: int = 50_000_000,
                 rows: list[Row] | None = None) -> list[str]:
    """A random tree of smoothly moving frames (3-D rotations, some static links).

    ``rows`` collects every link sample for the C++ side, flagged static or not."""
    names = [f"f{i}" for i in range(frames)]
    for i in range(1, frames):
        parent = names[rng.randrange(i)]
        if rng.random() < 0.2:
            tr = tuple(rng.uniform(-2, 2) for _ in range(3))
            q = _unit(rng)
            core.set_transform_static(_ts(parent, names[i], 0, tr, q))
            if rows is not None:
                rows.append((parent, names[i], 0, tr, q, True))
            continue
        p0 = [rng.uniform(-2, 2) for _ in range(3)]
        v = [rng.uniform(-1, 1) for _ in range(3)]
        axis = _unit3(rng)
        w = rng.uniform(-2, 2)
        q0 = _unit(rng)
        for k in range(samples):
            t = k * step_ns / SEC
            a = w * t
            dq = (*(c * math.sin(a / 2) for c in axis), math.cos(a / 2))
            tr = tuple(p0[j] + v[j] * t + 0.3 * math.sin(t + j) for j in range(3))
            q = _qmul(q0, dq)
            core.set_transform(_ts(parent, names[i], k * step_ns, tr, q))
            if rows is not None:
                rows.append((parent, names[i], k * step_ns, tr, q, False))
    return names


def _unit3(rng: random.Random) -> tuple[float, float, float]:
    v = [rng.gauss(0, 1) for _ in range(3)]
    n = math.sqrt(sum(c * c for c in v))
    return (v[0] / n, v[1] / n, v[2] / n)


def _unit(rng: random.Random) -> tuple[float, float, float, float]:
    v = [rng.gauss(0, 1) for _ in range(4)]
    n = math.sqrt(sum(c * c for c in v))
    return (v[0] / n, v[1] / n, v[2] / n, v[3] / n)


def _qmul(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, float, float, float]:
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)


def _apply(ts: TransformStamped, p: tuple[float, float, float]) -> tuple[float, float, float]:
    (tx, ty, tz), (x, y, z, w) = ts.transform
    # q p q*
    ix = w * p[0] + y * p[2] - z * p[1]
    iy = w * p[1] + z * p[0] - x * p[2]
    iz = w * p[2] + x * p[1] - y * p[0]
    iw = -x * p[0] - y * p[1] - z * p[2]
    return (ix * w + iw * -x + iy * -z - iz * -y + tx,
            iy * w + iw * -y + iz * -x - ix * -z + ty,
            iz * w + iw * -z + ix * -y - iy * -x + tz)


def test_origin_method_matches_finite_differences_of_lookups() -> None:
    rng = random.Random(7)
    checked = 0
    for _ in range(6):
        core = BufferCore(100.0)
        names = _random_tree(rng, core, step_ns=10_000_000, samples=200)
        for _ in range(20):
            tracking, observation, reference, pframe = (rng.choice(names) for _ in range(4))
            if tracking == observation:
                continue
            t = rng.randrange(400_000_000, 1_500_000_000)
            h = 100_000  # 100 µs: the window (200 µs) and the central difference agree to O(h²)
            point = tuple(rng.uniform(-1, 1) for _ in range(3))
            v = core.lookup_velocity_full(tracking, observation, reference, point, pframe,
                                          Time.from_ns(t), Duration.from_ns(2 * h),
                                          method="origin")
            # the point, fixed to the tracking frame, in the observation frame at t ± h
            at_t = core.lookup_transform(tracking, pframe, Time.from_ns(t))
            body_point = _apply(at_t, point)  # in tracking coordinates
            later = core.lookup_transform(observation, tracking, Time.from_ns(t + h))
            earlier = core.lookup_transform(observation, tracking, Time.from_ns(t - h))
            ahead, behind = _apply(later, body_point), _apply(earlier, body_point)
            fd = tuple((a - b) / (2 * h / SEC) for a, b in zip(ahead, behind, strict=True))
            # expressed in the reference frame's axes at t
            rot = core.lookup_transform(reference, observation, Time.from_ns(t))
            zero = _apply(rot, (0.0, 0.0, 0.0))
            fd_ref = tuple(a - b for a, b in zip(_apply(rot, fd), zero, strict=True))
            assert tuple(v.velocity.linear) == pytest.approx(fd_ref, abs=1e-6)
            checked += 1
    assert checked > 60


# ------------------------------------------------------------------ against C++ libtf


def _build_reference(tmp: Path) -> Path:
    require("ros1", "install_ros1.sh")  # libtf-dev, g++ and pkg-config with it
    flags = subprocess.run(["pkg-config", "--cflags", "--libs", "tf"], capture_output=True,
                           text=True, check=True)
    exe = tmp / "tf_velocity_ref"
    source = HERE.parent / "peers" / "debian" / "tf_velocity_ref.cpp"
    subprocess.run(["g++", "-O1", "-o", str(exe), str(source),
                    *flags.stdout.split()], check=True, timeout=300)
    return exe


@pytest.fixture(scope="module", name="reference_exe")
def reference_exe_fixture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _build_reference(tmp_path_factory.mktemp("tfref"))


def test_tf2_method_equals_cpp_libtf_lookup_twist(reference_exe: Path) -> None:
    rng = random.Random(2026)
    lines: list[str] = []
    ours: list[tuple[float, ...] | type] = []
    for _tree in range(12):
        # the C++ side gets one Transformer per run: distinct frame names per tree
        core = BufferCore(1000.0)
        rows: list[Row] = []
        names = _random_tree(rng, core, rows=rows)
        tag = f"t{_tree}_"
        for parent, child, ns, tr, q, static in rows:
            lines.append(f"{'P' if static else 'T'} {tag}{parent} {tag}{child} {ns} "
                         + " ".join(map(repr, (*tr, *q))))
        for _ in range(40):
            tracking, observation = rng.choice(names), rng.choice(names)
            t = rng.choice([0, rng.randrange(0, 2_100_000_000)])
            interval = rng.choice([rng.randrange(1_000_000, 500_000_000),
                                   rng.randrange(1, 20) * 50_000_000, 100_000_001])
            when, span = Time.from_ns(t), Duration.from_ns(interval)
            if rng.random() < 0.5:
                lines.append(f"S {tag}{tracking} {tag}{observation} {t} {interval}")
                call = partial(core.lookup_velocity, tracking, observation, when, span)
            else:
                reference, pframe = rng.choice(names), rng.choice(names)
                point = tuple(rng.uniform(-3, 3) for _ in range(3))
                lines.append(f"F {tag}{tracking} {tag}{observation} {tag}{reference} "
                             f"{point[0]!r} {point[1]!r} {point[2]!r} {tag}{pframe} {t} {interval}")
                call = partial(core.lookup_velocity_full, tracking, observation, reference,
                               point, pframe, when, span)
            try:
                v = call()
            except TransformException as e:
                ours.append(type(e))
            else:
                ours.append((*v.velocity.linear, *v.velocity.angular))
    out = subprocess.run([str(reference_exe)], input="\n".join(lines) + "\n", capture_output=True,
                         text=True, check=True, timeout=120).stdout.splitlines()
    assert len(out) == len(ours)
    compared = errors = 0
    for ref, mine in zip(out, ours, strict=True):
        if ref.startswith("ERR"):
            assert isinstance(mine, type), (ref, mine)
            errors += 1
            continue
        assert not isinstance(mine, type), (ref, mine)
        expected = [float(x) for x in ref.split()[1:]]
        for a, b in zip(mine, expected, strict=True):
            assert a == pytest.approx(b, abs=1e-9, rel=1e-9), (ref, mine)
        compared += 1
    assert compared > 250 and errors > 5, (compared, errors)


# ------------------------------------------------------------------ bad input


@pytest.mark.parametrize(
    ("interval", "needle"),
    [(0.0, "0.0"), (-0.1, "-0.1"), (math.nan, "nan"), (math.inf, "inf"),
     (Duration.from_ns(0), "0 ns"), ("1", "'1'"), (True, "True")],
)
def test_bad_averaging_interval(interval: object, needle: str) -> None:
    core = BufferCore(100.0)
    _moving_body(core)
    with pytest.raises(InvalidArgumentException, match="averaging_interval") as e:
        core.lookup_velocity("body", "world", Time(0), interval)  # type: ignore[arg-type]
    assert needle in str(e.value)


def test_bad_reference_point_method_and_time() -> None:
    core = BufferCore(100.0)
    _moving_body(core)
    for point in ((1, 2), (1, 2, math.nan), "abc", None):
        with pytest.raises(InvalidArgumentException, match="reference_point"):
            core.lookup_velocity_full("body", "world", "world", point, "body",  # type: ignore[arg-type]
                                      Time(0), 0.1)
    with pytest.raises(InvalidArgumentException, match=r"method.*'fast'"):
        core.lookup_velocity("body", "world", Time(0), 0.1, method="fast")
    with pytest.raises(InvalidArgumentException, match=r"time.*1\.5"):
        core.lookup_velocity("body", "world", 1.5, 0.1)  # type: ignore[arg-type]


def test_errors_of_the_lookups() -> None:
    core = BufferCore(100.0)
    _moving_body(core)
    from tfbus import ExtrapolationException, LookupException

    with pytest.raises(LookupException):
        core.lookup_velocity("body", "nowhere", Time(0), 0.1)
    with pytest.raises(ExtrapolationException):
        core.lookup_velocity("body", "world", Time.from_sec(10.0), 0.1, method="origin")


# ------------------------------------------------------------------ awaitable


@pytest.mark.anyio
async def test_buffer_lookup_velocity_async_waits_for_data() -> None:
    import anyio

    clock = ManualClock(Time(0))
    buf = Buffer(100.0, clock=clock)
    result: list[VelocityStamped] = []

    async def ask() -> None:
        result.append(await buf.lookup_velocity_async("body", "world", Time.from_sec(0.5), 0.1,
                                                      timeout=5.0))

    async with anyio.create_task_group() as tg:
        tg.start_soon(ask)
        await anyio.wait_all_tasks_blocked()
        assert not result
        for i in range(0, 101):
            t = i / 100
            buf.set_transform(_ts("world", "body", i * 10_000_000, (2 * t, 0, 0), _yaw(t)))
    assert result[0].velocity.linear.x == pytest.approx(2 * math.cos(0.5), abs=1e-9)
    full = await buf.lookup_velocity_full_async("body", "world", "body", (0, 0, 0), "body",
                                               Time.from_sec(0.5), 0.1, timeout=1.0,
                                               method="origin")
    assert full.velocity.linear.x == pytest.approx(2 * math.cos(0.5), abs=1e-9)


@pytest.mark.anyio
async def test_buffer_lookup_velocity_async_times_out() -> None:
    import anyio

    clock = ManualClock(Time(0))
    buf = Buffer(100.0, clock=clock)
    errors: list[BaseException] = []

    async def ask() -> None:
        try:
            await buf.lookup_velocity_async("body", "world", Time.from_sec(0.5), 0.1, timeout=2.0)
        except TimeoutException as e:
            errors.append(e)

    async with anyio.create_task_group() as tg:
        tg.start_soon(ask)
        await anyio.wait_all_tasks_blocked()
        await clock.advance(2.5)
    assert len(errors) == 1 and "body" in str(errors[0])
    assert buf.pending_waits == 0

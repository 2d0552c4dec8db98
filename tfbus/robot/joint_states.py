"""An animated joint_state_publisher: JointStates moving every joint within its limits.

::

    model = load_urdf("robot.urdf")
    sinusoidal_joint_state(model, stamp, seconds)    # one JointState at ``seconds``
    async with Bus() as bus:
        await publish_joint_states(bus, model)       # on /joint_states at 10 Hz

ROS's ``joint_state_publisher`` without its GUI publishes every movable joint at the
centre of its limits; this one sweeps them sinusoidally so that a robot_state_publisher
downstream (:class:`tfbus.robot.RobotStatePublisher`, ``tfbus robot-state-publisher``)
has something to show. Mimic joints are left to robot_state_publisher, as in ROS.
"""

from __future__ import annotations

import math

import anyio
import anyio.abc

from tfbus.bus import Bus
from tfbus.clock import Clock, SystemClock, every
from tfbus.messages import Header, JointState
from tfbus.robot.urdf import RobotModel
from tfbus.time import Time
from tfbus.topics import JOINT_STATES_TOPIC

__all__ = ["publish_joint_states", "sinusoidal_joint_state"]


def sinusoidal_joint_state(model: RobotModel, stamp: Time, seconds: float,
                           period: float = 4.0) -> JointState:
    """A JointState moving every movable, non-mimic joint of ``model`` sinusoidally
    within its limits, like joint_state_publisher without a GUI but animated.

    Joint k (in document order) is at ``mid + half * sin(2 pi seconds / period + k)``
    with ``mid``/``half`` the centre and half-range of its ``<limit>``; continuous joints
    (no limits) sweep -pi..pi. Mimic joints are left to robot_state_publisher.
    """
    names: list[str] = []
    positions: list[float] = []
    for k, joint in enumerate(j for j in model.joints if j.movable and j.mimic is None):
        lo, hi = joint.lower, joint.upper
        if joint.type == "continuous" or lo is None or hi is None or lo >= hi:
            lo, hi = (-math.pi, math.pi) if joint.type != "prismatic" else (0.0, 0.0)
        # Halved first: with limits of +-1e308, hi - lo would overflow to inf.
        mid, half = lo / 2.0 + hi / 2.0, hi / 2.0 - lo / 2.0
        names.append(joint.name)
        q = mid + half * math.sin(2.0 * math.pi * seconds / period + k)
        positions.append(min(max(q, lo), hi))
    return JointState(Header(stamp, ""), tuple(names), tuple(positions))


async def publish_joint_states(
    bus: Bus, model: RobotModel, *, rate: float = 10.0, clock: Clock | None = None,
    topic: str = JOINT_STATES_TOPIC, period: float = 4.0,
    task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
) -> None:
    """Publish :func:`sinusoidal_joint_state` on ``topic`` at ``rate`` Hz (clock time,
    drift-free), stamped ``clock.now()``, until cancelled.

    Raises:
        ValueError: if ``rate`` or ``period`` is not a positive finite number.
    """
    for what, value in (("rate", rate), ("period", period)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{what} must be a positive number, got {value!r}")
    clock = clock if clock is not None else SystemClock()
    start = clock.now()
    task_status.started()
    async for _ in every(1.0 / rate, clock=clock, immediate=True):
        now = clock.now()
        await bus.publish(topic, sinusoidal_joint_state(model, now, (now - start).to_sec(),
                                                        period))


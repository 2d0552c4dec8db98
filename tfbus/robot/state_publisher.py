"""robot_state_publisher: a URDF and joint states become ``/tf`` and ``/tf_static``.

::

    rsp = RobotStatePublisher("robot.urdf", frame_prefix="")
    rsp.static_transforms(stamp)           # every fixed joint, parent link -> child link
    rsp.transforms(joint_state)            # every moving joint named in the JointState
    async with Bus() as bus:
        await rsp.run(bus)                 # /joint_states in; /tf and latched /tf_static out

Semantics are ROS 1's ``robot_state_publisher`` 1.15 (``src/robot_state_publisher.cpp``,
``src/joint_state_listener.cpp``) with the link tree built as ``kdl_parser`` builds it,
checked transform for transform against recordings of the real node
(``tests/data/rsp/``, ``scripts/data/record_robot_state.py``):

* a **fixed** joint is a static transform: its origin (``xyz``, then ``rpy`` = rotations
  about the fixed x, y, z axes, REP 103 / URDF); a **planar** joint too (kdl_parser makes
  it a fixed segment, so the node publishes its origin on ``/tf_static`` and ignores its
  joint states); a **floating** joint is never published.
* a **revolute** or **continuous** joint at position q is ``origin * Rot(axis, q)`` (axis
  normalised, not clamped to limits); a **prismatic** one ``origin * Trans(q * axis)``.
* mimic joints follow their leader, ``multiplier * position + offset``, when the leader is
  in the message and they are not; names are resolved in sorted order (``std::map``) and
  a repeated name keeps its first position. Transforms come sorted by joint name.
* a JointState whose ``position`` is empty is ignored; one with a different number of
  names and positions is refused (:class:`JointStateError`), as the node does.
* a quaternion (x, y, z, w) is the origin's rotation times the joint's rotation about its
  axis, with the sign KDL's ``Rotation::GetQuaternion`` (Shepperd's method) gives: w > 0
  up to 120 degrees of rotation, past that the largest of x, y, z positive. Values and
  signs match the node to 1e-15 on every recorded case; the fixed joints' rotations are
  extracted from the matrix exactly as KDL does.
* all static transforms carry the one stamp given (the node reads its clock once per
  fixed joint, microseconds apart).
* ``frame_prefix`` is ROS 2's (``frame_prefix + link``, no separator added).

tfbus refuses NaN/±Inf positions (the node publishes NaN transforms that every tf2
listener then rejects), positions that are not numbers (``"0.1"``, ``True``: a float64 in
sensor_msgs) and prismatic moves whose translation overflows to ±Inf:
:class:`JointStateError` names them and carries the valid transforms computed beside
them, which :meth:`RobotStatePublisher.run` still publishes.
"""

from __future__ import annotations

import logging
import math
import numbers
import os
from dataclasses import dataclass, replace
from typing import Any

import anyio
import anyio.abc
import numpy as np
import numpy.typing as npt
from transforms3d.euler import euler2quat
from transforms3d.quaternions import quat2mat

from tfbus.bus import Bus
from tfbus.clock import Clock, SystemClock
from tfbus.errors import JointStateError
from tfbus.messages import (
    Header,
    JointState,
    Quaternion,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.robot.urdf import JointInfo, Mimic, RobotModel, load_urdf
from tfbus.time import Time
from tfbus.topics import JOINT_STATES_TOPIC, TF_STATIC_TOPIC, TF_TOPIC

__all__ = [
    "RobotStatePublisher",
    "RobotStateStatistics",
]

_log = logging.getLogger(__name__)

_F64 = npt.NDArray[np.float64]

_MAX_AHEAD_S = 1e9
"""The largest ``max_stamp_ahead`` (seconds): beyond it the bound would overflow the
int64 nanoseconds of a stamp (and bounds nothing)."""
_MAX_OTHER_NAMES = 1024
"""Joint names not in the model that :meth:`RobotStatePublisher.run` remembers for its rate
limit; past that they are all forgotten at once (and count as never published, as a name
the node has not heard yet)."""


@dataclass
class RobotStateStatistics:
    """Counters of :meth:`RobotStatePublisher.run`: JointState messages ``received``,
    ``published`` on /tf, skipped by the ``rate_limited`` check, ``invalid`` (not a
    JointState, or refused whole), ``refused_positions`` (NaN/Inf positions dropped),
    ``ahead`` (stamped further ahead of the clock than ``max_stamp_ahead`` allows) and
    ``transforms`` published on /tf."""

    received: int = 0
    published: int = 0
    rate_limited: int = 0
    invalid: int = 0
    refused_positions: int = 0
    transforms: int = 0
    ahead: int = 0


def _quaternions(r: _F64) -> _F64:
    """(N, 3, 3) rotation matrices -> (N, 4) quaternions (x, y, z, w), with the branch
    choice and signs of KDL ``Rotation::GetQuaternion`` (orocos_kdl ``frames.cpp``,
    Shepperd's method): w > 0 when the trace exceeds 1e-12, else the component of the
    largest diagonal entry is positive."""
    out = np.empty((r.shape[0], 4))
    m00, m11, m22 = r[:, 0, 0], r[:, 1, 1], r[:, 2, 2]
    trace = m00 + m11 + m22
    sx = r[:, 2, 1] - r[:, 1, 2]  # 4 w x
    sy = r[:, 0, 2] - r[:, 2, 0]  # 4 w y
    sz = r[:, 1, 0] - r[:, 0, 1]  # 4 w z
    pxy = r[:, 0, 1] + r[:, 1, 0]  # 4 x y
    pxz = r[:, 0, 2] + r[:, 2, 0]  # 4 x z
    pyz = r[:, 1, 2] + r[:, 2, 1]  # 4 y z
    a = trace > 1e-12
    if a.all():
        s = 0.5 / np.sqrt(trace + 1.0)
        out[:, 0], out[:, 1], out[:, 2], out[:, 3] = sx * s, sy * s, sz * s, 0.25 / s
        return out
    i = np.nonzero(a)[0]
    s = 0.5 / np.sqrt(trace[i] + 1.0)
    out[i] = np.stack([sx[i] * s, sy[i] * s, sz[i] * s, 0.25 / s], axis=1)
    bx = ~a & (m00 > m11) & (m00 > m22)
    by = ~a & ~bx & (m11 > m22)
    bz = ~a & ~bx & ~by
    for mask, d, rows in ((bx, m00 - m11 - m22, (None, pxy, pxz, sx)),
                          (by, m11 - m00 - m22, (pxy, None, pyz, sy)),
                          (bz, m22 - m00 - m11, (pxz, pyz, None, sz))):
        i = np.nonzero(mask)[0]
        if i.size:
            s = 2.0 * np.sqrt(1.0 + d[i])
            out[i] = np.stack([0.25 * s if v is None else v[i] / s for v in rows], axis=1)
    return out


def _origin_rotation(rpy: tuple[float, float, float]) -> _F64:
    """URDF ``rpy`` (fixed axes x, y, z = transforms3d 'sxyz') -> 3x3 rotation matrix."""
    return np.asarray(quat2mat(euler2quat(rpy[0], rpy[1], rpy[2], "sxyz")), dtype=np.float64)


def _number(value: object) -> float:
    """``value`` as a float when it is a real number (int, float, numpy scalar), else NaN:
    a str such as ``"0.1"`` or a bool is not a joint position (sensor_msgs' ``float64[]``)."""
    if type(value) is float:
        return value
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return math.nan
    return float(value)


def _shown(name: str) -> str:
    """A joint name for a message: as is when printable, else its repr (no terminal escapes)."""
    return name if name.isprintable() else repr(name)


def _warn(count: int, message: str, *args: object) -> None:
    """Log the 1st, 10th, 100th, ... occurrence only: a bad peer cannot flood the log."""
    if count == 1 or str(count).rstrip("0") == "1":
        _log.warning(message + " (%d so far)", *args, count)


def _kdl_flips(x: float, y: float, z: float, w: float) -> bool:
    """Whether KDL's ``Rotation::GetQuaternion`` returns -q for the rotation of the
    quaternion q: its branch is chosen on the matrix trace and diagonal (written from q
    with KDL's ``Rotation::Quaternion`` formulas), and the branch's component comes out
    positive (w for a trace above 1e-12, else x, y or z for the largest diagonal entry)."""
    xx, yy, zz, ww = x * x, y * y, z * z, w * w
    if 3.0 * ww - xx - yy - zz > 1e-12:
        return w < 0.0
    m00, m11, m22 = ww + xx - yy - zz, ww - xx + yy - zz, ww - xx - yy + zz
    if m00 > m11 and m00 > m22:
        return x < 0.0
    if m11 > m22:
        return y < 0.0
    return z < 0.0


_MovingJoint = tuple[str, str, bool, Vector3, tuple[float, float, float], Quaternion]


def _moving_joint(j: JointInfo, prefix: str) -> _MovingJoint:
    """Precomputed per moving joint: frame ids, rotates?, origin translation, the unit
    axis (in the joint frame for rotation, turned into the parent frame for translation,
    as kdl_parser's ``origin.M * axis``) and the origin rotation (KDL signs)."""
    basis = _origin_rotation(j.rpy)
    axis = np.asarray(j.axis, dtype=np.float64) / math.hypot(*j.axis)
    rotates = j.type != "prismatic"
    if not rotates:
        axis = basis @ axis
    (rotation,) = _quaternions(basis[None]).tolist()
    return (prefix + j.parent, prefix + j.child, rotates, Vector3(*j.xyz),
            (float(axis[0]), float(axis[1]), float(axis[2])), Quaternion(*rotation))


class RobotStatePublisher:
    """ROS's robot_state_publisher for one robot description.

    Args:
        model: URDF text, a path to a URDF file, a :class:`~tfbus.robot.RobotModel` or a
            ``urdf_parser_py`` Robot.
        frame_prefix: prepended to every link name in frame ids (ROS 2's parameter:
            plain concatenation, e.g. ``"robot1/"``).
        ignore_timestamp: :meth:`run` publishes every JointState, with no rate limit
            (ROS's ``ignore_timestamp``).

    Raises:
        URDFError: if the description is malformed (the message names the element).
        ImportError: if urdfdom-py is missing and ``model`` is not a RobotModel.
    """

    def __init__(self, model: str | bytes | os.PathLike[str] | RobotModel | Any, *,
                 frame_prefix: str = "", ignore_timestamp: bool = False) -> None:
        self.model: RobotModel = load_urdf(model)
        """The parsed, validated description."""
        if not isinstance(frame_prefix, str):
            raise TypeError(f"frame_prefix must be a str, not {type(frame_prefix).__name__}")
        self.frame_prefix = frame_prefix
        self.ignore_timestamp = bool(ignore_timestamp)
        self._statistics = RobotStateStatistics()
        moving = sorted((j for j in self.model.joints if j.movable), key=lambda j: j.name)
        self._moving = {j.name: _moving_joint(j, frame_prefix) for j in moving}
        self._mimic: list[tuple[str, Mimic]] = sorted(
            (j.name, j.mimic) for j in self.model.joints if j.mimic is not None)
        fixed = sorted((j for j in self.model.joints if j.type in ("fixed", "planar")),
                       key=lambda j: j.name)
        quats = _quaternions(np.array([_origin_rotation(j.rpy) for j in fixed]).reshape(-1, 3, 3))
        self._fixed = [
            (frame_prefix + j.parent, frame_prefix + j.child,
             Transform(Vector3(*j.xyz), Quaternion(*(float(v) for v in q))))
            for j, q in zip(fixed, quats, strict=True)
        ]

    # -- sans-I/O ---------------------------------------------------------------------

    def statistics(self) -> RobotStateStatistics:
        """A copy of the counters: what :meth:`run` did so far."""
        return replace(self._statistics)

    def static_transforms(self, stamp: Time) -> list[TransformStamped]:
        """The transform of every fixed (and planar) joint, parent link -> child link,
        stamped ``stamp``, sorted by joint name (``publishFixedTransforms``)."""
        return [TransformStamped(Header(stamp, parent), child, tf)
                for parent, child, tf in self._fixed]

    def positions(self, joint_state: JointState) -> dict[str, object]:
        """The positions robot_state_publisher uses for ``joint_state``: the message's
        (first occurrence of a repeated name wins), plus every mimic joint whose leader
        is there and which is not (``multiplier * leader + offset``). Values are as given
        (not yet checked); names that are not strings are dropped.

        Raises:
            JointStateError: if ``position`` is neither empty nor as long as ``name``.
        """
        try:
            names, values = joint_state.name, joint_state.position
            sizes = (len(names), len(values))
        except (AttributeError, TypeError):
            raise JointStateError(
                f"a JointState needs name and position sequences, got "
                f"{type(getattr(joint_state, 'name', None)).__name__} and "
                f"{type(getattr(joint_state, 'position', None)).__name__}") from None
        if sizes[1] == 0:
            return {}
        if sizes[0] != sizes[1]:
            raise JointStateError(f"a JointState with {len(names)} names and {len(values)} "
                                  f"positions (refused whole, as robot_state_publisher does)")
        out: dict[str, object] = {}
        for name, value in zip(names, values, strict=True):
            if isinstance(name, str) and name not in out:
                out[name] = value
        for follower, mimic in self._mimic:
            if mimic.joint in out and follower not in out:
                leader = out[mimic.joint]
                q = _number(leader)
                out[follower] = q * mimic.multiplier + mimic.offset if math.isfinite(q) else leader
        return out

    def transforms(self, joint_state: JointState) -> list[TransformStamped]:
        """The transform of every moving joint named in ``joint_state`` (and of the mimic
        joints following them), stamped with ``joint_state.header.stamp``, sorted by
        joint name. Unknown names, fixed, planar and floating joints are ignored; an empty
        ``position`` gives no transforms.

        Returns:
            A list of TransformStamped, parent link -> child link (with ``frame_prefix``).

        Raises:
            JointStateError: if the message is malformed (``name``/``position`` lengths
                differ, the stamp is not a Time) -- nothing is computed; or if some
                positions are NaN, ±Inf or not numbers -- ``.refused`` names them and
                ``.transforms`` holds the transforms of the other joints.
        """
        stamp = getattr(getattr(joint_state, "header", None), "stamp", None)
        if not isinstance(stamp, Time):
            raise JointStateError(f"JointState header.stamp must be a Time, not {stamp!r}")
        positions = self.positions(joint_state)
        moving = self._moving
        new = tuple.__new__
        result: list[TransformStamped] = []
        refused: dict[str, object] = {}
        for name in sorted(n for n in positions if n in moving):
            raw = positions[name]
            q = _number(raw)
            if not math.isfinite(q):
                refused[name] = raw
                continue
            parent, child, rotates, tr, (ax, ay, az), rot = moving[name]
            if rotates:
                # origin rotation (x1, y1, z1, w1) times the rotation by q about the axis
                x1, y1, z1, w1 = rot
                h = 0.5 * q
                sh = math.sin(h)
                bx, by, bz, bw = ax * sh, ay * sh, az * sh, math.cos(h)
                x = w1 * bx + x1 * bw + y1 * bz - z1 * by
                y = w1 * by - x1 * bz + y1 * bw + z1 * bx
                z = w1 * bz + x1 * by - y1 * bx + z1 * bw
                w = w1 * bw - x1 * bx - y1 * by - z1 * bz
                if _kdl_flips(x, y, z, w):
                    x, y, z, w = -x, -y, -z, -w
                transform = new(Transform, (tr, new(Quaternion, (x, y, z, w))))
            else:
                x, y, z = tr[0] + ax * q, tr[1] + ay * q, tr[2] + az * q
                if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
                    refused[name] = raw  # finite, but the translation overflows (1e308 m)
                    continue
                transform = new(Transform, (new(Vector3, (x, y, z)), rot))
            result.append(new(TransformStamped,
                              (new(Header, (stamp, parent)), child, transform)))
        if refused:
            shown = ", ".join(f"{_shown(name)}={value!r}" for name, value in refused.items())
            raise JointStateError(f"joint position(s) must be finite numbers: {shown} (the "
                                  f"other {len(result)} joint(s) were computed)",
                                  refused, result)
        return result

    # -- the node ---------------------------------------------------------------------

    async def run(
        self,
        bus: Bus,
        *,
        joint_states_topic: str = JOINT_STATES_TOPIC,
        publish_frequency: float = 20.0,
        max_stamp_ahead: float | None = None,
        clock: Clock | None = None,
        task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
    ) -> None:
        """Run the node on the open ``bus`` until cancelled.

        Subscribes to ``joint_states_topic``, publishes the fixed joints once on the
        latched ``/tf_static`` stamped ``clock.now()``, then reports started
        (``await tg.start(rsp.run, bus)``). Each JointState's moving joints go out as one
        TFMessage on ``/tf``, rate-limited as ROS 1's node does: published only when
        ``stamp >= least recent publish stamp of its joints + 1 / max(publish_frequency,
        1)`` seconds (unless ``ignore_timestamp``); a clock jump backwards resets that
        memory. As there, one JointState stamped ahead of the clock holds every later
        one back until the clock reaches its stamp (ROS 1 ``joint_state_listener.cpp``
        takes ``min(now, last publish stamps)``): an hour ahead, an hour of silence.
        ``max_stamp_ahead`` (seconds) is the way out: a JointState stamped more than
        that ahead of ``clock.now()`` is counted in ``statistics().ahead``, logged and
        dropped, remembered by nobody (None, the default: ROS's behaviour). Invalid
        messages are counted in :meth:`statistics` and logged, and
        never stop the node; with NaN/Inf positions the other joints are still published.
        Publish times are kept for the model's joints and for at most 1 024 other names
        (then those are forgotten at once), not for every name ever heard.

        Raises:
            ValueError: if ``publish_frequency`` is not a positive finite number, or
                ``max_stamp_ahead`` not a finite number >= 0.
            RuntimeError / anyio.ClosedResourceError: if the bus is not open / closed.
        """
        if not (isinstance(publish_frequency, (int, float)) and math.isfinite(publish_frequency)
                and publish_frequency > 0):
            raise ValueError(f"publish_frequency must be a positive number of Hz, "
                             f"got {publish_frequency!r}")
        ahead_ns: int | None = None
        if max_stamp_ahead is not None:
            if not (isinstance(max_stamp_ahead, (int, float))
                    and 0 <= max_stamp_ahead <= _MAX_AHEAD_S):
                raise ValueError(f"max_stamp_ahead must be seconds in [0, {_MAX_AHEAD_S:g}], "
                                 f"got {max_stamp_ahead!r}")
            ahead_ns = round(max_stamp_ahead * 1e9)
        clock = clock if clock is not None else SystemClock()
        interval = round(1e9 / max(float(publish_frequency), 1.0))
        last_publish: dict[str, int] = {}
        joints = frozenset(j.name for j in self.model.joints)
        bound = len(joints) + _MAX_OTHER_NAMES
        last_callback = refusals = 0
        stats = self._statistics
        with bus.subscribe(joint_states_topic) as sub:
            statics = self.static_transforms(clock.now())
            if statics:
                bus.publish_nowait(TF_STATIC_TOPIC, TFMessage(tuple(statics)))
            task_status.started()
            async for msg in sub:
                stats.received += 1
                if not isinstance(msg, JointState):
                    stats.invalid += 1
                    _warn(stats.invalid, "ignored a %s on %s (expected JointState)",
                          type(msg).__name__, joint_states_topic)
                    continue
                try:
                    stamp = msg.header.stamp.ns
                    names = list(msg.name)
                    sizes = (len(names), len(msg.position))
                except (AttributeError, TypeError):
                    stamp, sizes = -1, (0, 1)
                if sizes[0] != sizes[1] or stamp < 0:
                    if sizes[1]:  # an empty position is ignored quietly, as ROS does
                        stats.invalid += 1
                        _warn(stats.invalid, "ignored an invalid JointState on %s (%d names, "
                              "%d positions)", joint_states_topic, *sizes)
                    continue
                now = clock.now().ns
                if last_callback > now:  # moved backwards in time: re-publish
                    last_publish.clear()
                last_callback = now
                if ahead_ns is not None and stamp > now + ahead_ns:
                    stats.ahead += 1
                    _warn(stats.ahead, "ignored a JointState on %s stamped %.3f s ahead of "
                          "the clock (max_stamp_ahead %g s)", joint_states_topic,
                          (stamp - now) / 1e9, max_stamp_ahead)
                    continue
                keys = [n for n in names if isinstance(n, str)]
                least = min([now, *(last_publish.get(n, 0) for n in keys)])
                if not (self.ignore_timestamp or stamp >= least + interval):
                    stats.rate_limited += 1
                    continue
                try:
                    out = self.transforms(msg)
                except JointStateError as err:
                    stats.refused_positions += len(err.refused)
                    stats.invalid += not err.refused
                    refusals += 1
                    _warn(refusals, "%s", err)
                    out = err.transforms
                for n in keys:
                    if n not in last_publish and len(last_publish) >= bound and n not in joints:
                        # The node keeps a time for every name it ever hears: a peer sending
                        # new names would grow the map without bound. Past _MAX_OTHER_NAMES
                        # names that are not the model's, those are forgotten (as not heard).
                        for other in [k for k in last_publish if k not in joints]:
                            del last_publish[other]
                    last_publish[n] = stamp
                if out:
                    bus.publish_nowait(TF_TOPIC, TFMessage(tuple(out)))
                    stats.published += 1
                    stats.transforms += len(out)

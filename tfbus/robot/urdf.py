"""URDF robot descriptions read into a validated kinematic tree (no I/O but reading files).

::

    model = load_urdf("robot.urdf")        # a path, URDF text, or a urdf_parser_py Robot
    model.root, [j.name for j in model.joints]

Parsing is done by ``urdfdom-py`` (ROS's own ``urdf_parser_py``, the ``robot`` extra) on
an ``lxml`` tree parsed without DTDs, entities or network access. On top of it this module
checks what the C++ ``urdfdom`` parser behind ROS's ``urdf::Model`` refuses
(``urdf_parser/src/model.cpp``, ``joint.cpp``), so a description ROS would not load fails
here too, with one :class:`URDFError` naming the element: not well-formed XML, a root
element other than ``<robot>``, duplicate link or joint names, a joint whose parent or
child link is not defined, a link with two parent joints, loops, no root or two root
links, unknown joint types, a revolute or prismatic joint without ``<limit>``, numbers
that are not finite in origins, axes, ``<limit>`` and ``<mimic>`` (urdfdom's ``strToDouble``
cannot read ``nan``, ``inf`` or ``1e309``; ``1e308`` is a double and is accepted). Each
of these was checked to make ROS 1's robot_state_publisher 1.15 exit with an error. tfbus
also refuses a zero-length ``<axis>`` on a moving joint, which the node accepts and then publishes
as NaN transforms. A mimic of an unknown joint is accepted, as by the node (it never moves).

``<transmission>`` elements are dropped before parsing: ``urdf::Model`` ignores them and
urdfdom-py rejects the pr2_mechanism ones (PR2's description has them); ``<gazebo>``
and unknown elements are ignored, as by ``urdf::Model``.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tfbus.errors import URDFError

__all__ = ["JOINT_TYPES", "JointInfo", "Mimic", "RobotModel", "load_urdf"]

JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")
"""The joint types of the URDF specification (``urdf::Joint``)."""


@dataclass(frozen=True, slots=True)
class Mimic:
    """``<mimic joint= multiplier= offset=>``: position = ``multiplier * leader + offset``."""

    joint: str
    multiplier: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True, slots=True)
class JointInfo:
    """One ``<joint>`` of a URDF.

    Attributes:
        name, type, parent, child: as in the URDF (``type`` is one of :data:`JOINT_TYPES`).
        xyz: origin translation in the parent link, metres.
        rpy: origin rotation, fixed-axis roll, pitch, yaw about x, y, z (radians).
        axis: the joint axis in the joint frame as written (default (1, 0, 0)).
        lower, upper: ``<limit>`` bounds (radians or metres), ``None`` when absent.
        mimic: the joint this one follows, if any.
    """

    name: str
    type: str
    parent: str
    child: str
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    axis: tuple[float, float, float] = (1.0, 0.0, 0.0)
    lower: float | None = None
    upper: float | None = None
    mimic: Mimic | None = None

    @property
    def movable(self) -> bool:
        """True for the joint types robot_state_publisher moves from joint states."""
        return self.type in ("revolute", "continuous", "prismatic")


@dataclass(frozen=True, slots=True)
class RobotModel:
    """A validated URDF kinematic tree: ``name``, ``root`` link, ``links`` and ``joints``
    (document order)."""

    name: str
    root: str
    links: tuple[str, ...]
    joints: tuple[JointInfo, ...]

    def joint(self, name: str) -> JointInfo:
        """The joint called ``name``.

        Raises:
            KeyError: if there is no such joint.
        """
        for j in self.joints:
            if j.name == name:
                return j
        raise KeyError(name)


def load_urdf(model: str | bytes | os.PathLike[str] | RobotModel | Any) -> RobotModel:
    """Read and validate a robot description.

    Args:
        model: URDF text (``str`` or ``bytes`` starting with ``<``), a path to a URDF
            file, a :class:`RobotModel` (returned as is) or a ``urdf_parser_py`` Robot.

    Raises:
        URDFError: unreadable file, malformed XML, or a description ROS's urdf::Model
            refuses (see the module docstring); the message names the element.
        ImportError: if urdfdom-py is not installed (``pip install 'tfbus[robot]'``).
    """
    if isinstance(model, RobotModel):
        return model
    if isinstance(model, str) and model.lstrip("\ufeff \t\r\n").startswith("<"):
        return _from_text(model.lstrip("\ufeff"))
    if isinstance(model, bytes):
        if model.removeprefix(b"\xef\xbb\xbf").lstrip().startswith(b"<"):
            return _from_text(model)
        start = model[:20]
        raise URDFError("the robot description is empty" if not model.strip() else
                        f"the robot description is not XML: it starts with {start!r}")
    if isinstance(model, str) and not model.strip():
        raise URDFError("the robot description is empty (neither URDF text nor a path)")
    if isinstance(model, (str, os.PathLike)):
        path = Path(model)
        try:
            data = path.read_bytes()
        except OSError as err:
            raise URDFError(f"cannot read the URDF file {str(path)!r}: {err.strerror}") from err
        return _from_text(data)
    if hasattr(model, "joints") and hasattr(model, "links"):
        return _from_robot(model)
    raise TypeError(f"expected URDF text, a path or a parsed model, not {type(model).__name__}")


def _from_text(text: str | bytes) -> RobotModel:
    from lxml import etree
    from urdf_parser_py import urdf
    from urdf_parser_py.xml_reflection import core

    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False,
                             remove_comments=True)
    data = text.encode() if isinstance(text, str) else text
    try:
        root = etree.fromstring(data, parser)
    except etree.XMLSyntaxError as err:
        line = err.position[0] if err.position else 0
        raise URDFError(f"the robot description is not well-formed XML: line {line}: "
                        f"{err.msg}", f"line {line}") from None
    if not isinstance(root.tag, str) or root.tag != "robot":
        raise URDFError(f"the root element is <{root.tag}>, a URDF's is <robot>")
    # <link> and <joint> are taken out and read one by one below, as urdfdom-py's
    # AggregateElement.add_from_xml reads them: its Reflection.set_from_xml removes each
    # child it reads from the front of a list (list.remove), quadratic in their number.
    parts: list[Any] = []
    for child in list(root):
        if child.tag in ("transmission", "link", "joint"):
            root.remove(child)
        if child.tag in ("link", "joint"):
            parts.append(child)
        if child.tag == "joint":
            kind = child.get("type")
            if kind not in JOINT_TYPES:
                name = child.get("name")
                raise URDFError(f"joint {name!r} has unknown type {kind!r} (a URDF joint is "
                                f"one of {', '.join(JOINT_TYPES)})", f"joint {name!r}")
    warnings: list[str] = []
    saved = core.on_error
    core.on_error = warnings.append  # urdfdom-py reports unknown tags here; not fatal
    try:
        path = core.Path("robot", tree=etree.ElementTree(root))
        robot = urdf.URDF.from_xml(root, path)  # sets path.suffix to [@name='...']
        elements = urdf.URDF.XML_REFL.element_map
        count = {"link": 0, "joint": 0}
        for child in parts:
            count[child.tag] += 1
            where = core.Path(child.tag, parent=path, suffix=f"[{count[child.tag]}]")
            elements[child.tag].add_from_xml(robot, child, where)
    except Exception as err:
        what = str(getattr(err, "e", err)).strip().splitlines()
        where = str(getattr(err, "path", "robot"))
        raise URDFError(f"invalid URDF at {where}: {what[-1] if what else err!r}",
                        _element_of(where)) from None
    finally:
        core.on_error = saved
    return _from_robot(robot)


def _element_of(path: str) -> str:
    """``/robot[@name='r']/joint[@name='j']/origin`` -> ``joint 'j'``."""
    for kind in ("joint", "link"):
        marker = f"/{kind}[@name='"
        if marker in path:
            return f"{kind} {path.split(marker, 1)[1].split(chr(39), 1)[0]!r}"
    return "robot"


def _vector(value: Any, default: tuple[float, float, float], what: str,
            element: str) -> tuple[float, float, float]:
    if value is None:
        return default
    try:
        x, y, z = (float(v) for v in value)
    except (TypeError, ValueError):
        raise URDFError(f"{element}: {what} must be three numbers, got {value!r}",
                        element) from None
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        raise URDFError(f"{element}: {what} has a non-finite value {(x, y, z)!r}", element)
    return (x, y, z)


def _joint_info(j: Any) -> JointInfo:
    element = f"joint {j.name!r}"
    kind = j.type
    if kind not in JOINT_TYPES:
        raise URDFError(f"{element} has unknown type {kind!r} (a URDF joint is one of "
                        f"{', '.join(JOINT_TYPES)})", element)
    origin = j.origin
    xyz = _vector(getattr(origin, "xyz", None), (0.0, 0.0, 0.0), "origin xyz", element)
    rpy = _vector(getattr(origin, "rpy", None), (0.0, 0.0, 0.0), "origin rpy", element)
    axis = _vector(j.axis, (1.0, 0.0, 0.0), "axis", element)
    lower = upper = None
    if j.limit is not None:
        # urdfdom's parseJointLimits reads each with strToDouble (an istream), which
        # refuses nan, inf and values beyond the double range (1e309 reads as inf here).
        values = {}
        for what in ("lower", "upper", "effort", "velocity"):
            value = getattr(j.limit, what, None)
            number = 0.0 if value is None else float(value)
            if not math.isfinite(number):
                raise URDFError(f"{element}: <limit {what}=\"{value!r}\"> is not a finite "
                                f"number", element)
            values[what] = number
        lower, upper = values["lower"], values["upper"]
    elif kind in ("revolute", "prismatic"):
        # urdfdom's parseJoint: "Joint [..] is of type REVOLUTE but it does not specify limits"
        raise URDFError(f"{element} is {kind} but has no <limit>", element)
    if kind in ("revolute", "continuous", "prismatic") and math.hypot(*axis) == 0.0:
        raise URDFError(f"{element}: axis {axis!r} has zero length", element)
    mimic = None
    if j.mimic is not None:
        mul = 1.0 if j.mimic.multiplier is None else float(j.mimic.multiplier)
        off = 0.0 if j.mimic.offset is None else float(j.mimic.offset)
        if not (math.isfinite(mul) and math.isfinite(off)):
            raise URDFError(f"{element}: mimic multiplier/offset must be finite", element)
        mimic = Mimic(str(j.mimic.joint), mul, off)
    return JointInfo(str(j.name), kind, str(j.parent), str(j.child), xyz, rpy, axis,
                     lower, upper, mimic)


def _from_robot(robot: Any) -> RobotModel:
    links: list[str] = []
    known: set[str] = set()
    for link in robot.links:
        name = str(link.name)
        if name in known:
            raise URDFError(f"link {name!r} is defined twice", f"link {name!r}")
        links.append(name)
        known.add(name)
    if not links:
        raise URDFError("the robot has no <link>")
    joints: list[JointInfo] = []
    parent_joint: dict[str, str] = {}
    seen: set[str] = set()
    for j in robot.joints:
        info = _joint_info(j)
        element = f"joint {info.name!r}"
        if info.name in seen:
            raise URDFError(f"{element} is defined twice", element)
        seen.add(info.name)
        for role, link_name in (("parent", info.parent), ("child", info.child)):
            if link_name not in known:
                raise URDFError(f"{element}: its {role} link {link_name!r} is not defined",
                                element)
        if info.parent == info.child:
            raise URDFError(f"{element}: link {info.child!r} is its own parent (a loop)",
                            element)
        if info.child in parent_joint:
            raise URDFError(f"link {info.child!r} has two parent joints, "
                            f"{parent_joint[info.child]!r} and {info.name!r}",
                            f"link {info.child!r}")
        parent_joint[info.child] = info.name
        joints.append(info)
    roots = [name for name in links if name not in parent_joint]
    if len(roots) > 1:
        raise URDFError(f"two root links, {roots[0]!r} and {roots[1]!r}: a URDF is one tree "
                        f"(a joint must connect them)", f"link {roots[1]!r}")
    if not roots:
        first = joints[0].name
        raise URDFError(f"no root link: every link has a parent, the joints form a loop "
                        f"(through joint {first!r})", f"joint {first!r}")
    children: dict[str, list[str]] = {}
    for info in joints:
        children.setdefault(info.parent, []).append(info.child)
    reached = {roots[0]}
    todo = [roots[0]]
    while todo:
        for child in children.get(todo.pop(), ()):
            reached.add(child)
            todo.append(child)
    if len(reached) != len(links):
        looped = next(info for info in joints if info.child not in reached)
        raise URDFError(f"joint {looped.name!r} is part of a loop: link {looped.child!r} "
                        f"cannot be reached from the root link {roots[0]!r}",
                        f"joint {looped.name!r}")
    return RobotModel(str(robot.name), roots[0], tuple(links), tuple(joints))

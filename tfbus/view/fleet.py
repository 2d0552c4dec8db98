"""The fleet selector of ``tfbus view``: on a ``namespace=*`` bus (a
:class:`~tfbus.fleet.FleetBuffer` with ``merged=True``, every robot's frames prefixed with
its name, ``robot7/base_link``, tf_prefix style) or a bag of such frames, one robot or all
of them side by side.

A robot is the first ``/``-separated part of a frame id (:func:`robot_of`); the robots a
fleet bus announces (liveliness) are listed even before their first transform. Each robot
is drawn in its own fixed frame (:func:`robot_fixed_frame`): the frame named like the
page's fixed frame in the robot's namespace (pick ``robot1/odom`` and every robot is drawn
from its ``odom``), else the root of the robot's largest tree. With "all robots" the robots
are drawn side by side along x, sorted by name: robot ``k``'s fixed frame at
``(k x slot, 0, 0)``, ``slot`` the x extent of all the robots' frames together (each
robot's frames in its own fixed frame) plus :data:`GAP` metres, grown and never shrunk
(robots do not jump about as they move), so no two robots' frames overlap.

The robot dropdown lists at most :data:`MAX_ROBOTS_LISTED` robots (the rest counted);
names are shown as text (:func:`tfbus.view.escape.text`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from typing import TYPE_CHECKING, Any

from tfbus.core import BufferCore
from tfbus.messages import Transform, TransformStamped, Vector3
from tfbus.time import Time
from tfbus.view.escape import html_text as _h
from tfbus.view.escape import text
from tfbus.view.scene import (
    DEFAULT_FRAME_TIMEOUT,
    NO_PARENT,
    FrameView,
    Scene,
    fade,
)
from tfbus.view.tree import descendants

if TYPE_CHECKING:
    from tfbus.view.server import TfPage

__all__ = [
    "ALL_ROBOTS",
    "GAP",
    "MAX_ROBOTS_LISTED",
    "MIN_SLOT",
    "FleetView",
    "robot_fixed_frame",
    "robot_of",
]

_LATEST = Time(0)

ALL_ROBOTS = "all robots"
"""The robot dropdown's first choice: every robot, side by side."""
GAP = 2.0
"""Metres between the frames of two robots drawn side by side."""
MIN_SLOT = 4.0
"""Metres from one robot's fixed frame to the next one's at least."""
MAX_ROBOTS_LISTED = 100
"""Robots in the dropdown at most (a fleet keeps at most ``max_robots``; the rest are
counted in the panel)."""


def robot_of(frame_id: str) -> str | None:
    """The robot of a fleet frame id (``"robot7"`` for ``"robot7/base_link"``); None for an
    id without a namespace (no ``/`` after a non-empty first part)."""
    head, sep, rest = frame_id.partition("/")
    return head if sep and head and rest else None


def robot_fixed_frame(robot: str, frames: Iterable[str], parents: Mapping[str, str],
                      fixed_frame: str | None) -> str | None:
    """The frame ``robot`` is drawn from: ``robot/<name>`` when ``fixed_frame`` is
    ``<other robot>/<name>`` (or ``<name>``) and ``robot`` has that frame, else the root of
    its largest tree (most frames; the first by id on a tie), None without frames."""
    names = list(frames)
    if fixed_frame is not None:
        other = robot_of(fixed_frame)
        rest = fixed_frame.partition("/")[2] if other is not None else fixed_frame
        candidate = f"{robot}/{rest}"
        if candidate in names:
            return candidate
    trees = descendants({c: p for c, p in parents.items() if c in set(names)}, names)
    if not trees:
        return None
    return max(sorted(trees), key=lambda r: len(trees[r]))


def _shifted(pose: TransformStamped, dx: float) -> TransformStamped:
    t = pose.transform
    v = t.translation
    return TransformStamped(pose.header, pose.child_frame_id,
                            Transform(Vector3(v.x + dx, v.y, v.z), t.rotation))


class FleetView:
    """The page's "fleet" folder: a robot dropdown (:data:`ALL_ROBOTS` or one robot) and
    a line per robot drawn (its fixed frame and where it is placed); :meth:`build` makes
    the scene the page draws (module doc).

    Args:
        page: the page (the folder is added to its side panel).
        robots: the robots known besides those with frames (a fleet bus's
            :meth:`~tfbus.fleet.FleetBuffer.robots`); None: those with frames only.
    """

    def __init__(self, page: TfPage, robots: Callable[[], Iterable[str]] | None = None
                 ) -> None:
        self._page = page
        self._robots = robots
        gui = page.server.gui
        with gui.add_folder("fleet"):
            self.dropdown: Any = gui.add_dropdown(
                "robot", options=(ALL_ROBOTS,), initial_value=ALL_ROBOTS,
                hint="one robot, or all of them side by side")
            self.html: Any = gui.add_html("")
        self.dropdown.on_update(self._on_pick)
        self.choice: str | None = None
        """The robot picked in the page (None: all robots)."""
        self.slot = MIN_SLOT
        """Metres from one robot's fixed frame to the next one's (grows, never shrinks)."""
        self.offsets: dict[str, float] = {}
        """x offset (metres) of each robot drawn by the last :meth:`build`."""
        self.fixed_frames: dict[str, str] = {}
        """The fixed frame of each robot drawn by the last :meth:`build`."""
        self.robots: tuple[str, ...] = ()
        """Every robot known at the last :meth:`build`, sorted."""
        self.html_value = ""
        self._options: dict[str, str] = {}

    def _on_pick(self, event: Any) -> None:
        if event.client is None:
            return
        page = self._page
        with page._lock:
            value = str(self.dropdown.value)
            self.choice = None if value == ALL_ROBOTS else self._options.get(value, self.choice)
            page.control_version += 1

    def pick(self, robot: str | None) -> None:
        """Show only ``robot`` (None: all robots), as the dropdown does."""
        self.choice = robot

    def build(self, core: BufferCore, *, fixed_frame: str | None = None,
              time: Time = _LATEST, now: Time | None = None,
              last_update: Mapping[str, Time] | None = None,
              frame_timeout: float = DEFAULT_FRAME_TIMEOUT) -> Scene:
        """The scene of the robots picked: each frame's pose is
        ``core.lookup_transform(robot's fixed frame, frame, time)``, moved along x by the
        robot's offset (all robots) or not (one robot); ages and fade as
        :func:`~tfbus.view.scene.build_scene`. The scene's ``fixed_frame`` is the first
        robot's; frames outside any namespace are left out (counted in the panel).

        Raises:
            ValueError: ``frame_timeout`` is not positive.
        """
        fade(None, frame_timeout)
        names = core.get_frame_names()
        info = {i.child: i for i in core.frame_info()}
        parents = {c: i.parent for c, i in info.items() if i.parent != NO_PARENT}
        groups: dict[str, list[str]] = {}
        outside = 0
        for name in names:
            robot = robot_of(name)
            if robot is None:
                outside += 1
            else:
                groups.setdefault(robot, []).append(name)
        known = set(groups)
        if self._robots is not None:
            known.update(self._robots())
        self.robots = tuple(sorted(known))
        self._show_options()
        picked = [self.choice] if self.choice in groups else sorted(groups)
        if self.choice is not None and self.choice not in groups:
            picked = []
        views: list[FrameView] = []
        by_robot: dict[str, list[FrameView]] = {}
        fixed_frames: dict[str, str] = {}
        for robot in picked:
            frames = groups[robot]
            fixed = robot_fixed_frame(robot, frames, parents, fixed_frame)
            if fixed is None:
                continue
            fixed_frames[robot] = fixed
            out: list[FrameView] = []
            for name in frames:
                fi = info.get(name)
                parent = parents.get(name)
                static = fi.is_static if fi is not None else False
                res = core.try_lookup_transform(fixed, name, time)
                pose = res if isinstance(res, TransformStamped) else None
                age: float | None = None
                if not static and now is not None and last_update is not None \
                        and name in last_update:
                    age = max(0.0, (now.ns - last_update[name].ns) / 1e9)
                out.append(FrameView(
                    frame_id=name, parent=parent, static=static, pose=pose,
                    error=None if pose is not None else str(res), age=age,
                    colour=fade(age, frame_timeout),
                    authority=fi.authority if fi is not None else None))
            by_robot[robot] = out
        offsets = {r: 0.0 for r in by_robot}
        if self.choice is None and len(by_robot) > 1:
            xs = [f.pose.transform.translation.x for fs in by_robot.values() for f in fs
                  if f.pose is not None]
            if xs:
                self.slot = max(self.slot, max(xs) - min(xs) + GAP)
            offsets = {r: k * self.slot for k, r in enumerate(sorted(by_robot))}
        for robot, fs in by_robot.items():
            dx = offsets[robot]
            views.extend(f if f.pose is None or dx == 0.0 else
                         FrameView(f.frame_id, f.parent, f.static, _shifted(f.pose, dx),
                                   f.error, f.age, f.colour, f.authority) for f in fs)
        self.offsets, self.fixed_frames = offsets, fixed_frames
        lines = [f"{_h(r)}: fixed frame {_h(fixed_frames[r])}, x {offsets[r]:+.2f} m"
                 for r in sorted(by_robot)]
        listed = self.robots[:MAX_ROBOTS_LISTED]
        if len(self.robots) > len(listed):
            lines.append(f"{len(self.robots) - len(listed)} more robots not listed")
        waiting = [r for r in self.robots if r not in groups][:10]
        if waiting:
            lines.append("no frames yet: " + ", ".join(_h(r) for r in waiting))
        if outside:
            lines.append(f"{outside} frames outside any robot's namespace not drawn")
        value = "<p class='tfbus-fleet' style='font-size:0.8em'>" + "<br>".join(lines) + "</p>"
        if value != self.html_value:
            self.html_value = value
            self.html.content = value
        first = next(iter(sorted(fixed_frames)), None)
        message = None
        if not views:
            message = ("no robot's frames received" if self.choice is None
                       else f"no frames of robot {text(self.choice)} received")
        return Scene(fixed_frames[first] if first is not None else None, time,
                     tuple(views), message)

    def _show_options(self) -> None:
        options = {text(r): r for r in self.robots[:MAX_ROBOTS_LISTED]}
        if options != self._options:
            self._options = options
            self.dropdown.options = (ALL_ROBOTS, *sorted(options))
        shown = ALL_ROBOTS if self.choice is None else text(self.choice)
        if shown in (ALL_ROBOTS, *options) and self.dropdown.value != shown:
            self.dropdown.value = shown

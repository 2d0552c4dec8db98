"""The scene model of ``tfbus view``: every frame's pose in a fixed frame, its parent, its
fade state and tf2's message when it cannot be placed (no web library imported here).

The fade follows rviz's TF display ("Frame Timeout", default 15 s): a frame updated less
than a third of the timeout ago is drawn in full colour; between a third and the whole
timeout its colour fades linearly to grey; older than the timeout it is hidden. Static
frames (``/tf_static``) never fade: a static transform holds for ever, as tf2 treats it.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Final, cast

from tfbus.core import BufferCore
from tfbus.messages import TransformStamped
from tfbus.time import Time

_LATEST: Final = Time(0)
NO_PARENT: Final = "NO_PARENT"
"""The parent :meth:`BufferCore.frame_info` reports for a link emptied by ``clear()``."""

__all__ = ["DEFAULT_FRAME_TIMEOUT", "FrameView", "Scene", "build_scene",
           "default_fixed_frame", "fade"]

DEFAULT_FRAME_TIMEOUT: Final = 15.0
"""rviz's TF display "Frame Timeout", seconds: a frame not updated for this long is hidden."""


def fade(age: float | None, timeout: float = DEFAULT_FRAME_TIMEOUT) -> float | None:
    """How much colour a frame updated ``age`` seconds ago keeps: ``1.0`` (full colour)
    for ``age <= timeout / 3``, then linearly down to ``0.0`` (grey) at ``age == timeout``,
    ``None`` (hidden) beyond. ``age=None`` (never updated: static, or a root) is ``1.0``.

    Raises:
        ValueError: ``timeout`` is not a positive finite number.
    """
    if not (timeout > 0.0 and timeout != float("inf")):
        raise ValueError(f"frame timeout must be a positive number of seconds, got {timeout!r}")
    if age is None:
        return 1.0
    third = timeout / 3.0
    if age <= third:
        return 1.0
    if age > timeout:
        return None
    return (timeout - age) / (timeout - third)


@dataclass(frozen=True, init=False)
class FrameView:
    """One frame as the page draws it.

    ``pose`` is ``lookup_transform(fixed_frame, frame_id, time)`` (it maps points of the
    frame into the fixed frame; translation in metres, rotation a unit quaternion), or
    ``None`` with ``error`` set to the core's own exception text when it cannot be placed.
    ``age`` is seconds since the frame's last update (``None`` when unknown: static or a
    root); ``colour`` is :func:`fade` of it (``None``: hidden). Ids are kept exactly as
    received (markup and control characters included): drawing them as text is the
    page's job.
    """

    frame_id: str
    parent: str | None
    static: bool
    pose: TransformStamped | None
    error: str | None
    age: float | None
    colour: float | None
    authority: str | None = None

    def __init__(self, frame_id: str, parent: str | None, static: bool,
                 pose: TransformStamped | None, error: str | None, age: float | None,
                 colour: float | None, authority: str | None = None) -> None:
        # The fields stored as the dataclass's own frozen __init__ stores them, in one
        # dict write each instead of an object.__setattr__ call each (a redraw makes one
        # view per frame: a third of the time of building a scene of 100 frames went here).
        d = self.__dict__
        d["frame_id"] = frame_id
        d["parent"] = parent
        d["static"] = static
        d["pose"] = pose
        d["error"] = error
        d["age"] = age
        d["colour"] = colour
        d["authority"] = authority

    @property
    def visible(self) -> bool:
        """Drawn at all: placed in the fixed frame and not timed out."""
        return self.pose is not None and self.colour is not None

    @property
    def stale(self) -> bool:
        """Fading or hidden: not updated for more than a third of the timeout."""
        return self.colour is None or self.colour < 1.0


@dataclass(frozen=True)
class Scene:
    """Every frame of a buffer seen from ``fixed_frame`` at ``time``, in registration
    order; ``message`` says why the scene is empty (no transforms)."""

    fixed_frame: str | None
    time: Time
    frames: tuple[FrameView, ...]
    message: str | None = None

    def frame(self, frame_id: str) -> FrameView:
        """The view of ``frame_id``; ``KeyError`` naming it if the scene has none."""
        for f in self.frames:
            if f.frame_id == frame_id:
                return f
        raise KeyError(frame_id)


def _parents(links: Iterable[tuple[str, str, str, bool, int, int, int]]) -> dict[str, str]:
    """Child -> parent of every frame with a parent, from the core's ``link_info``
    tuples (``frame_info``'s entries unnamed: child, parent, ...)."""
    return {link[0]: link[1] for link in links if link[1] != NO_PARENT}


def _largest_root(names: list[str], parents: Mapping[str, str]) -> str | None:
    """:func:`default_fixed_frame` of the frames ``names`` (registration order) linked
    by ``parents`` (child -> parent). Each frame's root is found once: a walk up stops
    at the first frame whose root is already known, and every frame it passed gets that
    root, so the whole tree costs O(frames) however deep it is. A frame on a loop, or
    below one, has no root (a walk that meets a frame it passed itself: marked
    :data:`_WALKING` while the walk is under way)."""
    roots: dict[str, object] = {}
    sizes: dict[str, int] = {}
    get_root = roots.get
    for name in names:
        root = get_root(name, _UNKNOWN)
        if root is _UNKNOWN:
            path: list[str] = []
            frame = name
            while True:
                root = get_root(frame, _UNKNOWN)
                if root is not _UNKNOWN:
                    if root is _WALKING:  # a loop: no root for any frame on this walk
                        root = None
                    break
                parent = parents.get(frame)
                if parent is None:
                    root = roots[frame] = frame
                    break
                roots[frame] = _WALKING
                path.append(frame)
                frame = parent
            for passed in path:
                roots[passed] = root
        if root is not None:
            key = cast("str", root)
            sizes[key] = sizes.get(key, 0) + 1
    if not sizes:
        return None
    order = {n: i for i, n in enumerate(names)}
    return max(sizes, key=lambda r: (sizes[r], -order.get(r, 0)))


_UNKNOWN: Final = object()
"""A frame whose root :func:`_largest_root` has not found yet."""
_WALKING: Final = object()
"""A frame on the walk :func:`_largest_root` is making (met again: a loop)."""


def default_fixed_frame(core: BufferCore) -> str | None:
    """The root of the largest tree (most frames; the first registered on a tie), as rviz
    users pick ``map``/``odom``/``world``; ``None`` for an empty buffer. A loop has no
    root: its frames count for none."""
    return _largest_root(core.get_frame_names(), _parents(core.link_info()))


def build_scene(
    core: BufferCore,
    *,
    fixed_frame: str | None = None,
    time: Time = _LATEST,
    now: Time | None = None,
    last_update: Mapping[str, Time] | None = None,
    frame_timeout: float = DEFAULT_FRAME_TIMEOUT,
    last_update_ns: Mapping[str, int] | None = None,
) -> Scene:
    """The scene of ``core`` seen from ``fixed_frame`` (default: :func:`default_fixed_frame`)
    at ``time`` (``Time(0)``: the latest data, as rviz draws a live tree).

    Args:
        core: the transforms (read only).
        fixed_frame: the frame at the origin of the page.
        time: the lookup time of every pose.
        now: the clock's time, for ages; ``None`` leaves every age unknown (full colour).
        last_update: when each frame was last updated (receive time live, record time in
            a bag); a frame missing from it has no age.
        frame_timeout: seconds (see :func:`fade`).
        last_update_ns: ``last_update`` as integer nanoseconds, read instead of it when
            given (a live view has them so: no :class:`~tfbus.time.Time` made per frame
            and redraw).

    Returns:
        A :class:`Scene`; ``pose`` of each frame equals
        ``core.lookup_transform(fixed_frame, frame_id, time)`` and ``error`` is the
        message that call raises (tf2's text, e.g. ``Could not find a connection between
        'a' and 'b' because they are not part of the same tree...``).

    Raises:
        ValueError: ``frame_timeout`` is not positive.
    """
    fade(None, frame_timeout)  # validates the timeout
    names = core.get_frame_names()
    # frame_info's entries as the core's plain tuples (child, parent, authority,
    # is_static, ...): one FrameInfo fewer per frame and redraw
    info = {i[0]: i for i in core.link_info()}
    if fixed_frame is None:  # default_fixed_frame, from the links read here
        fixed_frame = _largest_root(names, _parents(info.values()))
    if not names or fixed_frame is None:
        return Scene(fixed_frame, time, (), "no transforms received (no /tf or /tf_static)")
    received: Mapping[str, int] | None = last_update_ns
    if received is None and last_update is not None:
        received = {name: t.ns for name, t in last_update.items()}
    now_ns = now.ns if now is not None else None
    lookup = core.try_lookup_transform
    views: list[FrameView] = []
    for name in names:
        fi = info.get(name)
        if fi is None:
            parent, static, authority = None, False, None
        else:
            parent = fi[1] if fi[1] != NO_PARENT else None
            static, authority = fi[3], fi[2]
        out = lookup(fixed_frame, name, time)
        pose = out if isinstance(out, TransformStamped) else None
        error = None if pose is not None else str(out)
        age: float | None = None
        if not static and now_ns is not None and received is not None:
            last = received.get(name)
            if last is not None:
                age = max(0.0, (now_ns - last) / 1e9)
        views.append(FrameView(name, parent, static, pose, error, age,
                               fade(age, frame_timeout), authority))
    message = None
    if not core.frame_exists(fixed_frame):
        message = f"fixed frame [{fixed_frame}] does not exist"
    return Scene(fixed_frame, time, tuple(views), message)

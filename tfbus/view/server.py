"""The page of ``tfbus view``: a viser server drawing a :class:`~tfbus.view.scene.Scene`
(needs the ``tfbus[view]`` extra).

Per frame an axes triad at its pose in the fixed frame (x red, y green, z blue: line
segments, so their colour can fade) with a text label of its id, a line from each child
to its parent (axes and line coloured by :func:`~tfbus.view.scene.fade`, as rviz's TF
display: full colour, fading to grey, hidden), a grid, and a side panel with the frame
tree (parent, rate, age, state, broadcaster: one line per frame, "static" for a static
link's rate) and tf2's message for each frame that cannot be placed.
Ids reach the page as text only: the panel is HTML built here with every id through
:func:`html.escape` (control characters also written as ``\\xNN`` escapes), and scene
labels are viser's text labels. Scene node names are numbered (``/tf/f3``), never made
from ids, so a ``/`` in an id cannot re-parent a node.
"""

from __future__ import annotations

import functools
import itertools
import threading
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from tfbus.core import BufferCore, frame_path
from tfbus.errors import PortInUseError
from tfbus.messages import TransformStamped
from tfbus.monitor import TfSummary
from tfbus.time import Time
from tfbus.view.escape import html_text as _h
from tfbus.view.escape import text
from tfbus.view.graph import GraphView
from tfbus.view.guard import PageGuard, check_port
from tfbus.view.robot import LinkVisual
from tfbus.view.scene import Scene
from tfbus.view.trails import (
    DEFAULT_TRAIL_SECONDS,
    MAX_TRAIL_SECONDS,
    MIN_TRAIL_SECONDS,
    Trail,
    TrailSampler,
    check_seconds,
)
from tfbus.view.tree import FrameTree

if TYPE_CHECKING:
    from tfbus.doctor import Finding

__all__ = ["PortInUseError", "TfPage", "text"]

FULL_COLOUR = (230, 140, 20)
"""Colour of a fresh link line (RGB 0-255); it fades to :data:`GREY`."""
GREY = (128, 128, 128)
"""What a frame's axes and link line fade to at the frame timeout (rviz's TF display)."""
CHAIN_COLOUR = (220, 0, 220)
"""Colour of the links of the chain between the two frames picked in the page."""
TRAIL_COLOUR = (0, 170, 200)
"""Colour of the trail of the frame picked in the page's "trail" folder (RGB 0-255)."""
AXES_COLOURS = ((230, 30, 30), (30, 190, 30), (40, 80, 240))
"""Full colour of the x, y and z axis of a frame (RGB 0-255)."""
_PANEL_BOX = "overflow-x:auto;max-width:100%"
_PANEL_TABLE = "font-size:0.75em;white-space:nowrap;border-spacing:0.6em 0"
# cells never wrap (an id is one line); a table wider than the panel scrolls sideways

MAX_FINDINGS_SHOWN = 50
"""Findings listed in the page's doctor panel at most (the most severe first); the rest
are counted in one line."""
_LEVEL_COLOURS = {"error": "#d03030", "warning": "#c08000", "info": "#3070c0"}

AXES_LENGTH = 0.25
"""Length of each drawn axis, metres (the page's "axis length" slider starts there)."""
MAX_FILTER_LENGTH = 200
"""Characters a frame filter may have; a longer one is refused with an error line."""
FILTER_TIMEOUT = 0.01
"""Seconds one frame filter search may take (the ``regex`` package's ``timeout``): a
pattern that backtracks catastrophically (``(a|aa)+$``) is dropped, with an error line,
instead of stalling the drawing loop (Python's own ``re`` cannot be interrupted)."""


def _xyz(pose: TransformStamped) -> tuple[float, float, float]:
    v = pose.transform.translation
    return (v.x, v.y, v.z)


@functools.lru_cache(maxsize=4096)
def _mix(colour: float, full: tuple[int, int, int] = FULL_COLOUR) -> tuple[int, int, int]:
    """``full`` faded towards :data:`GREY`: ``colour`` 1.0 is ``full``, 0.0 grey."""
    r, g, b = (round(grey + (f - grey) * colour) for f, grey in zip(full, GREY, strict=True))
    return (r, g, b)


@functools.lru_cache(maxsize=4096)
def _axes_block(colour: float) -> npt.NDArray[np.uint8]:
    """The x, y and z axes' :func:`_mix` of ``colour`` as a read-only ``(3, 2, 3) uint8``
    array (sRGB 0-255; each axis segment's two ends): a redraw gathers one per frame
    (:func:`_blocks`)."""
    return _segment_block([_mix(colour, full) for full in AXES_COLOURS])


@functools.lru_cache(maxsize=4096)
def _link_block(colour: float) -> npt.NDArray[np.uint8]:
    """:func:`_mix` of ``colour`` as a read-only ``(1, 2, 3) uint8`` array (a link
    segment's two ends, sRGB 0-255)."""
    return _segment_block([_mix(colour)])


def _segment_block(colours: list[tuple[int, int, int]]) -> npt.NDArray[np.uint8]:
    """A read-only ``(len(colours), 2, 3) uint8`` array: each segment's two ends in its
    sRGB colour (cached blocks are shared by every redraw, so none may be written)."""
    block = np.array([(c, c) for c in colours], dtype=np.uint8).reshape(len(colours), 2, 3)
    block.setflags(write=False)
    return block


_NO_COLOURS: npt.NDArray[np.uint8] = _segment_block([])


def _blocks(fades: list[float],
            block: Callable[[float], npt.NDArray[np.uint8]]) -> npt.NDArray[np.uint8]:
    """``block(fade)`` of each of ``fades``, one after the other: ``(K len(fades), 2, 3)
    uint8`` (sRGB 0-255) for blocks of ``K`` segments. Made once per distinct fade (a
    redraw of live frames has one or a few), then gathered for every frame at once."""
    if not fades:
        return _NO_COLOURS
    first = fades[0]
    if fades.count(first) == len(fades):  # one fade (all full colour, say): one block
        one = block(first)
        return np.broadcast_to(one, (len(fades), *one.shape)).reshape(-1, 2, 3)
    index: dict[float, int] = {}
    which = [index.setdefault(f, len(index)) for f in fades]
    table = np.stack([block(f) for f in index])
    out: npt.NDArray[np.uint8] = table[np.asarray(which, dtype=np.intp)].reshape(-1, 2, 3)
    return out


def _to_linear(srgb: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8]:
    """sRGB 0-255 as the linear 0-255 values viser's per-vertex line colours are (its
    client divides by 255 and three.js encodes the output as sRGB): sent so, a colour is
    shown as given (the IEC 61966-2-1 transfer function)."""
    out: npt.NDArray[np.uint8] = _LINEAR[srgb]
    return out


def _linear_table() -> npt.NDArray[np.uint8]:
    c = np.arange(256, dtype=np.float64) / 255.0
    lin = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    out: npt.NDArray[np.uint8] = np.round(lin * 255.0).astype(np.uint8)
    return out


_LINEAR = _linear_table()
""":func:`_to_linear` of each sRGB value 0-255 (a table: a redraw converts every
vertex colour)."""


def _rotation_terms() -> tuple[npt.NDArray[np.intp], npt.NDArray[np.float64],
                                npt.NDArray[np.intp], npt.NDArray[np.float64]]:
    """The rotation matrix of a unit quaternion (x, y, z, w) minus the identity, entry by
    entry, as two of its pairwise products ``q_i q_j`` (index ``4 i + j``, i, j = x, y,
    z, w = 0..3) times a coefficient each: ``(first, first_coefficient, second,
    second_coefficient)``, ``(9,)`` each, entry ``3 k + r`` being entry r of the
    matrix's column k (the unit vector of axis k turned). The coefficients are those of
    the usual quaternion-to-matrix formula (e.g. ``transforms3d.quaternions.quat2mat``)."""
    x, y, z, w = range(4)
    terms = {  # (column k, entry r): the two (coefficient, i, j); the diagonal's 1 apart
        (0, 0): ((-2, y, y), (-2, z, z)), (0, 1): ((2, x, y), (2, w, z)),
        (0, 2): ((2, x, z), (-2, w, y)), (1, 0): ((2, x, y), (-2, w, z)),
        (1, 1): ((-2, x, x), (-2, z, z)), (1, 2): ((2, y, z), (2, w, x)),
        (2, 0): ((2, x, z), (2, w, y)), (2, 1): ((2, y, z), (-2, w, x)),
        (2, 2): ((-2, x, x), (-2, y, y)),
    }  # fmt: skip
    ordered = [terms[divmod(e, 3)] for e in range(9)]
    return (np.array([4 * i + j for (_, i, j), _ in ordered], dtype=np.intp),
            np.array([float(c) for (c, _, _), _ in ordered]),
            np.array([4 * i + j for _, (_, i, j) in ordered], dtype=np.intp),
            np.array([float(c) for _, (c, _, _) in ordered]))


_FIRST, _FIRST_COEFFICIENT, _SECOND, _SECOND_COEFFICIENT = _rotation_terms()
_EYE9 = np.eye(3).ravel()


def _axes(origins: npt.NDArray[np.float64], quaternions: npt.NDArray[np.float64],
          length: float = AXES_LENGTH) -> npt.NDArray[np.float64]:
    """The x, y, z axis segments of frames at ``origins`` (``(N, 3)`` metres) turned by
    ``quaternions`` (``(N, 4)`` x, y, z, w, unit): ``(3 N, 2, 3)``, for each frame origin
    to origin + R e_k x ``length`` (metres), k = x, y, z. R is made from the quaternion's
    pairwise products (:func:`_rotation_terms`): a handful of array operations for every
    frame at once, whatever their number (and no BLAS call, whose threads would spin)."""
    n = len(quaternions)
    products = (quaternions[:, :, None] * quaternions[:, None, :]).reshape(n, 16)
    cols = (products[:, _FIRST] * _FIRST_COEFFICIENT
            + products[:, _SECOND] * _SECOND_COEFFICIENT + _EYE9).reshape(n, 3, 3)
    out = np.empty((n, 3, 2, 3))
    out[:, :, 0, :] = origins[:, None, :]
    np.multiply(cols, length, out=out[:, :, 1, :])
    out[:, :, 1, :] += origins[:, None, :]
    return out.reshape(-1, 2, 3)


class _PoseSender:
    """Sets one viser node's position (and orientation), one message each, the change
    already known (:class:`DrawnFrame` compares exactly): queued as viser's own setters
    queue it, without their ``np.allclose`` check of each value against the last one sent
    (about 40 % of a redraw of 100 moving frames). The node's internals and viser's
    queue are looked up once, when the sender is made (a redraw sends one label position
    per frame). A viser without that path (its internals moved) gets the public setters."""

    __slots__ = ("_handle", "_impl", "_name", "_orientation", "_position", "_queue")

    def __init__(self, handle: Any) -> None:
        self._handle = handle
        impl = getattr(handle, "_impl", None)
        queue = getattr(getattr(impl, "api", None), "_queue_scene_message", None)
        messages = _viser_messages()
        if impl is None or queue is None or messages is None:
            self._impl: Any = None
            return
        self._impl = impl
        self._name = impl.name
        self._queue = queue
        self._position = messages.SetPositionMessage
        self._orientation = messages.SetOrientationMessage

    def send(self, xyz: tuple[float, float, float],
             wxyz: tuple[float, float, float, float] | None = None) -> None:
        """Move the node to ``xyz`` (metres) and, when given, turn it to ``wxyz`` (a unit
        quaternion w, x, y, z)."""
        impl = self._impl
        if impl is None:
            self._handle.position = xyz
            if wxyz is not None:
                self._handle.wxyz = wxyz
            return
        impl.position[:] = xyz
        self._queue(self._position(self._name, xyz))
        if wxyz is not None:
            impl.wxyz[:] = wxyz
            self._queue(self._orientation(self._name, wxyz))


@functools.cache
def _viser_messages() -> Any:
    """viser's message classes (``SetPositionMessage``, ``SetOrientationMessage``), or
    None when this viser has them elsewhere."""
    try:
        from viser import _messages
    except ImportError:
        return None
    if hasattr(_messages, "SetPositionMessage") and hasattr(_messages,
                                                            "SetOrientationMessage"):
        return _messages
    return None


class DrawnFrame:
    """One frame as the page draws it: :attr:`position` (metres) and :attr:`wxyz` (unit
    quaternion w, x, y, z) in the fixed frame as last drawn, :attr:`visible` (its axes
    drawn), :attr:`name` (its scene node, the parent of its ``--urdf`` geometry).

    What reaches a browser is only what it shows: the label gets a position (a label has
    no orientation) while it is shown, the node a pose only when geometry hangs on it
    (the axes and links of every frame are one line-segments node each), and each
    message only when its value changed since the last one sent, compared exactly.
    """

    def __init__(self, node: Any, label: Any, posed: bool) -> None:
        self.node = node
        """The viser frame node (no axes of its own: hidden, or moved with its geometry)."""
        self.label = label
        """The viser label with the frame id as text."""
        self.name: str = str(node.name)
        self.visible = False
        self.posed = posed
        """Whether the node itself is moved (it carries ``--urdf`` geometry)."""
        self._pose: tuple[tuple[float, float, float],
                          tuple[float, float, float, float]] | None = None
        self._label_at: tuple[float, float, float] | None = None
        self._node_shown: bool | None = None
        self._label_shown: bool | None = None
        self._node_sender = _PoseSender(node)
        self._label_sender = _PoseSender(label)

    def place(self, xyz: tuple[float, float, float],
              wxyz: tuple[float, float, float, float]) -> None:
        """Put the frame at ``xyz`` (metres), ``wxyz`` in the fixed frame; nothing is
        sent when the pose is the one already drawn."""
        pose = (xyz, wxyz)
        if pose == self._pose:
            return
        self._pose = pose
        if self.posed:
            self._node_sender.send(xyz, wxyz)

    @property
    def position(self) -> npt.NDArray[np.float64]:
        """``(3,) float64``, metres: the position last drawn (zeros before any)."""
        return np.array(self._pose[0] if self._pose is not None else (0.0, 0.0, 0.0),
                        dtype=np.float64)

    @property
    def wxyz(self) -> npt.NDArray[np.float64]:
        """``(4,) float64``: the orientation last drawn, a unit quaternion w, x, y, z
        (the identity before any)."""
        return np.array(self._pose[1] if self._pose is not None else (1.0, 0.0, 0.0, 0.0),
                        dtype=np.float64)

    def show(self, drawn: bool, labels: bool) -> None:
        """Show or hide the frame (``drawn``) and its label (``drawn and labels``); a label
        shown gets the frame's position first."""
        self.visible = drawn
        if drawn is not self._node_shown:
            self.node.visible = drawn
            self._node_shown = drawn
        label = drawn and labels
        pose = self._pose
        if label and pose is not None and self._label_at != pose[0]:
            self._label_sender.send(pose[0])
            self._label_at = pose[0]
        if label is not self._label_shown:
            self.label.visible = label
            self._label_shown = label


class TfPage:
    """A viser server showing tf frames; :meth:`draw` puts a scene on it.

    Args:
        host: address to bind (``127.0.0.1`` by default: this machine only).
        port: TCP port; 0 picks a free one (:attr:`port` says which).
        title: first line of the side panel.
        token: a secret a browser must carry (``?token=``) to be let in from a name other
            than this machine's (:mod:`tfbus.view.guard`); None: loopback names only.

    Every request's ``Host`` and ``Origin`` are checked (:attr:`guard`): another site
    the user visits cannot read the frames nor drive playback; refused requests, failed
    handshakes and unreadable messages are counted there and logged as one line.

    Raises:
        PortInUseError: ``port`` is taken.
        ValueError: ``token`` is not a valid token (:class:`~tfbus.view.guard.PageGuard`).
        ImportError: viser is not installed (``pip install 'tfbus[view]'``).
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 8080, *,
                 title: str = "tfbus view", token: str | None = None) -> None:
        import viser

        from tfbus.view import guard

        PageGuard(host, port, token)  # a bad token is refused before anything is bound
        guard.install()
        check_port(host, port)
        self.server: Any = viser.ViserServer(host=host, port=port, verbose=False)
        self.port: int = int(self.server.get_port())
        if port and self.port != port:
            self.server.stop()
            raise PortInUseError(f"cannot serve on {host}:{port}: address already in use")
        self.guard = PageGuard(host, self.port, token)
        """The ``Host`` / ``Origin`` / token check and its counters (``refused``,
        ``failed_handshakes``, ``bad_messages``)."""
        guard.register(self.guard)
        self.host = host
        self._lock = threading.Lock()
        self.server.scene.set_up_direction("+z")
        self.server.scene.add_grid("/grid", width=20.0, height=20.0, cell_size=1.0,
                                   section_size=5.0, plane="xy")
        self.frames: dict[str, DrawnFrame] = {}
        """Each frame id drawn (``position``, ``wxyz``, ``visible``, ``name``)."""
        self.labels: dict[str, Any] = {}
        """Viser label of each frame id drawn (``text``, ``visible``)."""
        self.camera_set = False
        """Whether the camera was aimed at the frames (once, at the first frames drawn)."""
        self.visuals: dict[str, list[Any]] = {}
        """Geometry handles per link frame id (children of the frame's scene node)."""
        self._pending_visuals: dict[str, list[LinkVisual]] = {}
        self.clouds: dict[str, Any] = {}
        """Point cloud handle per scan topic (``points``: ``(N, 3) float32``)."""
        self.links: Any = None
        self.link_count = 0
        self.axes: Any = None
        """The line segments of every visible frame's axes (``points``, ``colors``:
        ``(3 N, 2, 3)``), three rows per frame in :attr:`axes_rows`' order."""
        self.axes_count = 0
        # each line-segments node's points, sRGB colours and linear colours as last sent
        self._segments_sent: dict[str, tuple[npt.NDArray[np.float32], npt.NDArray[np.uint8],
                                             npt.NDArray[np.uint8]]] = {}
        self.axes_rows: dict[str, int] = {}
        """First row in :attr:`axes` of each frame drawn now (hidden frames have none)."""
        self._axes_srgb: npt.NDArray[np.uint8] = _NO_COLOURS  # (3 N, 2, 3) sRGB, as drawn
        gui = self.server.gui
        self._title = gui.add_html(f"<b>{_h(title)}</b>")
        self.status = gui.add_html("")
        self.control_version = 0
        """Incremented each time a browser changes a display control (fixed frame,
        filter, labels, axis length): a paused bag is drawn again at once."""
        self.fixed_frame_choice: str | None = None
        """The fixed frame picked in the page's dropdown (None: not picked; the scene's
        own choice, ``--fixed-frame`` or the root of the largest tree, is used)."""
        self.frame_filter: Any = None
        """The page's frame filter (a compiled ``regex`` pattern searched in each id,
        within :data:`FILTER_TIMEOUT` s; None: every frame)."""
        self.filter_error_html = ""
        self._fixed_options: dict[str, str] = {}
        self._fixed_ids: tuple[str, ...] | None = None  # the frame ids they were made of
        with gui.add_folder("display"):
            self.fixed_dropdown: Any = gui.add_dropdown(
                "fixed frame", options=("",), initial_value="",
                hint="the frame at the origin: every frame is looked up in it")
            self.filter_box: Any = gui.add_text(
                "frame filter", "", hint="a Python regular expression searched in each "
                "frame id; empty: every frame")
            self.filter_error = gui.add_html("")
            self.labels_box: Any = gui.add_checkbox("labels", initial_value=True)
            self.axis_length: Any = gui.add_slider(
                "axis length (m)", min=0.05, max=2.0, step=0.05, initial_value=AXES_LENGTH)
        with gui.add_folder("two frames (tf_monitor A B)"):
            self.pair_dropdowns: tuple[Any, Any] = (
                gui.add_dropdown("frame A", options=("",), initial_value="",
                                 hint="the target frame: B's pose is shown in A"),
                gui.add_dropdown("frame B", options=("",), initial_value="",
                                 hint="the source frame"))
            self.pair = gui.add_html("")
        self.pair_html = ""
        """The two frames' panel as last sent: the chain and B's pose in A."""
        self.pair_choice: tuple[str | None, str | None] = (None, None)
        """The frames picked as A and B (None: not picked)."""
        self.chain: Any = None
        """The highlighted links of the chain between A and B (line segments)."""
        self.chain_count = 0
        self._pair_options: tuple[str, ...] = ()
        with gui.add_folder("trail"):
            self.trail_dropdown: Any = gui.add_dropdown(
                "trail frame", options=("",), initial_value="",
                hint="the frame whose origin's path in the fixed frame is drawn")
            self.trail_seconds_box: Any = gui.add_number(
                "trail seconds", initial_value=DEFAULT_TRAIL_SECONDS,
                min=MIN_TRAIL_SECONDS, max=MAX_TRAIL_SECONDS, step=0.5,
                hint="how far back the trail reaches")
            self.trail_info = gui.add_html("")
        self.trail_choice: str | None = None
        """The frame whose trail is drawn (None: no trail, the default)."""
        self.trail_seconds = DEFAULT_TRAIL_SECONDS
        """How far back the trail reaches, seconds."""
        self.trail: Trail | None = None
        """The trail as last drawn (None: none drawn)."""
        self.trail_html = ""
        self.trail_line: Any = None
        """The trail's line segments (``points``: ``(K - 1, 2, 3)``)."""
        self.trail_count = 0
        self._trail_error = ""
        self._trails = TrailSampler()
        self.trail_dropdown.on_update(self._on_trail)
        self.trail_seconds_box.on_update(self._on_trail_seconds)
        for k, dropdown in enumerate(self.pair_dropdowns):
            dropdown.on_update(functools.partial(self._on_pair, k=k))
        self.fixed_dropdown.on_update(self._on_fixed)
        self.filter_box.on_update(self._on_filter)
        self.labels_box.on_update(self._on_control)
        self.axis_length.on_update(self._on_control)
        self._axes_length_sent = AXES_LENGTH
        self.tree = gui.add_html("")
        self.notes = gui.add_html("")
        self.frame_tree = FrameTree(gui, self._lock, self._controls_changed)
        """The browsable frame tree with a show/hide box per frame (:mod:`tfbus.view.tree`)."""
        with gui.add_folder("tf doctor"):
            self.findings = gui.add_html("")
        self.graph = GraphView(gui, self._lock, self._controls_changed)
        """The graph view of the tree (:mod:`tfbus.view.graph`), drawn when ticked."""
        self.findings_html = ""
        """The doctor panel's HTML as last sent (:meth:`set_findings`)."""
        self.notes_html = ""
        """The notes' HTML as last sent (:meth:`set_notes`)."""
        self.panel_html = ""
        """The frame tree panel's HTML as last sent."""
        self.status_html = ""
        self._connect_listeners: list[Callable[[], None]] = []
        self.server.on_client_connect(self._client_connected)

    # ------------------------------------------------------------------ controls

    def _on_fixed(self, event: Any) -> None:
        if event.client is None:  # our own write (the scene's fixed frame shown)
            return
        with self._lock:
            choice = self._fixed_options.get(str(self.fixed_dropdown.value))
            if choice is not None:
                self.fixed_frame_choice = choice
                self.control_version += 1

    def _on_pair(self, event: Any, k: int) -> None:
        if event.client is None:
            return
        with self._lock:
            value = str(self.pair_dropdowns[k].value)
            frame = self._fixed_options.get(value)
            pair = list(self.pair_choice)
            pair[k] = frame
            self.pair_choice = (pair[0], pair[1])
            self.control_version += 1

    def _on_trail(self, event: Any) -> None:
        if event.client is None:
            return
        with self._lock:
            self.trail_choice = self._fixed_options.get(str(self.trail_dropdown.value))
            self.control_version += 1

    def _on_trail_seconds(self, event: Any) -> None:
        if event.client is None:
            return
        with self._lock:
            try:
                self.trail_seconds = check_seconds(self.trail_seconds_box.value)
                self._trail_error = ""
            except (TypeError, ValueError) as err:  # the previous duration stays
                self._trail_error = str(err)
            self.control_version += 1

    def set_trail(self, frame_id: str | None, seconds: float | None = None) -> None:
        """Draw the trail of ``frame_id`` (None: no trail) over the last ``seconds``
        (None: unchanged), as the page's "trail" folder does (:mod:`tfbus.view.trails`).

        Raises:
            ValueError: ``seconds`` is not between :data:`~tfbus.view.trails.MIN_TRAIL_SECONDS`
                and :data:`~tfbus.view.trails.MAX_TRAIL_SECONDS`.
        """
        with self._lock:
            if seconds is not None:
                self.trail_seconds = check_seconds(seconds)
                self.trail_seconds_box.value = self.trail_seconds
            self.trail_choice = frame_id
            shown = "" if frame_id is None else text(frame_id)
            if shown in self._fixed_options or not shown:
                self.trail_dropdown.value = shown
            self.control_version += 1

    def _on_filter(self, event: Any) -> None:
        if event.client is None:
            return
        self.set_frame_filter(str(self.filter_box.value))

    def _controls_changed(self) -> None:
        """A display control changed (the caller holds ``_lock``): a paused bag is drawn
        again at once."""
        self.control_version += 1

    def _on_control(self, event: Any) -> None:
        if event.client is not None:
            with self._lock:
                self.control_version += 1

    def set_frame_filter(self, pattern: str) -> str | None:
        """Show only the frames whose id matches ``pattern`` (a regular expression
        searched in the id, as rviz2's TF display filter; empty: every frame). An invalid
        pattern (or one over :data:`MAX_FILTER_LENGTH` characters) is not applied: the
        previous filter stays and the error is shown under the box and returned."""
        import regex

        error: str | None = None
        compiled: Any = None
        if len(pattern) > MAX_FILTER_LENGTH:
            error = f"frame filter: longer than {MAX_FILTER_LENGTH} characters"
        elif pattern:
            try:
                compiled = regex.compile(pattern)
            except regex.error as err:
                error = f"frame filter: invalid regular expression {pattern!r}: {err}"
        self._filter_result(compiled, error)
        return error

    def _filter_result(self, compiled: Any, error: str | None) -> None:
        with self._lock:
            self._apply_filter(compiled, error)

    def _apply_filter(self, compiled: Any, error: str | None) -> None:
        """Set the filter (when ``error`` is None) and the error line under the box; the
        caller holds ``_lock`` (the drawing loop does, while it calls :meth:`shown`)."""
        value = "" if error is None else f"<p style='color:#d03030'>{_h(error)}</p>"
        if error is None:
            self.frame_filter = compiled
        if value != self.filter_error_html:
            self.filter_error_html = value
            self.filter_error.content = value
        self.control_version += 1

    def shown(self, frame_id: str) -> bool:
        """Whether the frame filter lets ``frame_id`` be drawn (called by the drawing
        loop, under ``_lock``). A search that takes longer than :data:`FILTER_TIMEOUT` s
        drops the filter (every frame is drawn) and says so under the box."""
        pattern = self.frame_filter
        if pattern is None:
            return True
        try:
            return pattern.search(frame_id, timeout=FILTER_TIMEOUT) is not None
        except TimeoutError:
            # called while drawing, under _lock: no second acquire
            self.frame_filter = None
            self._apply_filter(None, f"frame filter: {pattern.pattern!r} took longer than "
                                     f"{FILTER_TIMEOUT * 1000:g} ms on one frame id; not applied")
            return True

    def _show_fixed(self, scene: Scene) -> None:
        """The dropdown's options (every frame id, as text, sorted) and value (the scene's
        fixed frame). The options are made again only when the scene's frame ids are not
        those of the last redraw (each id is escaped to make them: about 3 % of a redraw
        of 100 frames whose ids did not change)."""
        ids = tuple([f.frame_id for f in scene.frames])
        if ids != self._fixed_ids:
            self._fixed_ids = ids
            options = {text(frame_id): frame_id for frame_id in ids}
            if options.keys() != self._fixed_options.keys():
                self._fixed_options = options
                self.fixed_dropdown.options = tuple(sorted(options)) or ("",)
                for dropdown in (*self.pair_dropdowns, self.trail_dropdown):
                    dropdown.options = ("", *sorted(options))
        shown = text(scene.fixed_frame) if scene.fixed_frame is not None else ""
        if shown in self._fixed_options and self.fixed_dropdown.value != shown:
            self.fixed_dropdown.value = shown

    # ------------------------------------------------------------------ viewers

    def watched(self) -> bool:
        """Whether a browser is connected now (one let in by :attr:`guard`)."""
        return bool(self.server.get_clients())

    def on_connect(self, listener: Callable[[], None]) -> None:
        """Call ``listener()`` each time a browser connects (from viser's thread: it must
        be quick, thread-safe and must not raise)."""
        with self._lock:
            self._connect_listeners.append(listener)

    def _client_connected(self, _client: Any) -> None:
        with self._lock:
            listeners = list(self._connect_listeners)
        for listener in listeners:
            listener()

    # ------------------------------------------------------------------ drawing

    def set_status(self, message: str | None) -> None:
        """One line above the tree (an empty scene's reason, a damaged bag, a time)."""
        value = "" if not message else f"<p>{_h(message)}</p>"
        if value != self.status_html:
            self.status_html = value
            self.status.content = value

    def draw(self, scene: Scene, stats: TfSummary | None = None,
             rates: Mapping[str, float] | None = None, core: BufferCore | None = None,
             *, table: bool = True) -> None:
        """Show ``scene``: frames, labels, links, and with ``table`` the frame table
        (else the table shown stays as it is). ``stats`` gives broadcasters and rates
        (Hz) when known; ``rates`` overrides a rate per frame; ``core`` (the buffer the
        scene was built from) answers the two frames' lookup (:meth:`draw_pair`)."""
        # one batch: viser's loop is woken once per redraw, not once per changed value,
        # and a browser applies the redraw's poses together
        with self._lock, self.server.atomic():
            self._draw(scene, stats, rates, table)
            self.draw_pair(scene, core, stats, rates)
            self.draw_trail(scene, core)
            self.frame_tree.update(scene, self.shown if self.frame_filter is not None else None,
                                   self.frame_filter)
            self.graph.update(scene)

    def draw_trail(self, scene: Scene, core: BufferCore | None) -> None:
        """The trail of :attr:`trail_choice` over the last :attr:`trail_seconds` of
        ``core`` in the scene's fixed frame (:class:`~tfbus.view.trails.TrailSampler`),
        as line segments in :data:`TRAIL_COLOUR`, and a line saying its points and span
        or tf2's message. Called by :meth:`draw` (the caller holds the lock)."""
        frame = self.trail_choice
        trail: Trail | None = None
        segments: npt.NDArray[np.float64] = np.zeros((0, 2, 3))
        value = ""
        if frame is not None and core is not None and scene.fixed_frame is not None:
            trail = self._trails.sample(core, scene.fixed_frame, frame, self.trail_seconds)
            if trail.error is not None:
                value = f"<p>trail of {_h(frame)}: {_h(trail.error)}</p>"
            else:
                span = (int(trail.stamps[-1]) - int(trail.stamps[0])) / 1e9
                value = (f"<p class='tfbus-trail'>trail of {_h(frame)} in "
                         f"{_h(scene.fixed_frame)}: {len(trail.points)} points over "
                         f"{span:.2f} s</p>")
                segments = trail.segments()
        # Set once, sampled: a reader in another thread (a test's, an embedding app's)
        # sees the trail drawn before or this one, never None while one is drawn.
        self.trail = trail
        if self._trail_error:
            value += f"<p style='color:#d03030'>{_h(self._trail_error)}</p>"
        colours = np.empty((len(segments), 2, 3), dtype=np.uint8)
        colours[:] = TRAIL_COLOUR
        self.trail_line, self.trail_count = self._segments(
            "/trail", self.trail_line, self.trail_count, segments, colours, 3.0)
        if value != self.trail_html:
            self.trail_html = value
            self.trail_info.content = value

    def _draw(self, scene: Scene, stats: TfSummary | None,
              rates: Mapping[str, float] | None, table: bool = True) -> None:
        poses = {f.frame_id: f.pose for f in scene.frames}
        ends: list[float] = []  # each link's two ends, x y z each: one flat list
        link_fades: list[float] = []  # each link's colour (its child's fade)
        origins: list[tuple[float, float, float]] = []
        quaternions: list[tuple[float, float, float, float]] = []
        axes_fades: list[float] = []  # each drawn frame's colour (fade)
        rows: dict[str, int] = {}
        length = float(self.axis_length.value)
        labels = bool(self.labels_box.value)
        hidden = self.frame_tree.hidden  # unticked in the page's frame tree
        frames = self.frames
        # the filter's test only while a filter is set (it drops itself on a timeout)
        shown = self.shown if self.frame_filter is not None else None
        for f in scene.frames:
            frame_id = f.frame_id
            pose = f.pose
            colour = f.colour
            drawn = (pose is not None and colour is not None  # f.visible
                     and (shown is None or shown(frame_id)) and frame_id not in hidden)
            record = frames.get(frame_id)
            if record is None:
                record = self._add_frame(frame_id)
            if pose is None:
                record.show(drawn, labels)
                continue
            tr = pose.transform
            v = tr.translation
            q = tr.rotation
            xyz = (v.x, v.y, v.z)
            record.place(xyz, (q.w, q.x, q.y, q.z))
            record.show(drawn, labels)
            if not drawn:
                continue
            assert colour is not None  # drawn: visible
            rows[frame_id] = 3 * len(origins)
            origins.append(xyz)
            quaternions.append((q.x, q.y, q.z, q.w))
            axes_fades.append(colour)
            parent = f.parent
            parent_pose = poses.get(parent) if parent is not None else None
            if parent_pose is not None:
                ends += xyz
                ends += _xyz(parent_pose)
                link_fades.append(colour)
        for name, drawn_frame in self.frames.items():  # drawn before, not in this scene
            if name not in poses and drawn_frame.visible:
                drawn_frame.show(False, labels)
        self.links, self.link_count = self._segments(
            "/links", self.links, self.link_count,
            np.array(ends, dtype=np.float32).reshape(-1, 2, 3),
            _blocks(link_fades, _link_block), 2.0)
        axes = (_axes(np.asarray(origins, dtype=np.float64),
                      np.asarray(quaternions, dtype=np.float64), length)
                if origins else np.zeros((0, 2, 3)))
        axes_srgb = _blocks(axes_fades, _axes_block)
        self.axes, self.axes_count = self._segments(
            "/axes", self.axes, self.axes_count, axes, axes_srgb, 4.0)
        self.axes_rows = rows
        self._axes_srgb = axes_srgb
        if not self.camera_set:
            self.aim(scene)
        self._show_fixed(scene)
        if table:
            self._draw_panel(scene, stats, rates)
        msg = scene.message
        if msg is None and scene.fixed_frame is not None:
            msg = f"fixed frame: {scene.fixed_frame}"
        self.set_status(msg)

    def draw_pair(self, scene: Scene, core: BufferCore | None,
                  stats: TfSummary | None = None,
                  rates: Mapping[str, float] | None = None) -> None:
        """The two frames picked in the page (:attr:`pair_choice`), as ``tf_monitor A B``
        shows them (tf2_ros ``tf_monitor.cpp``): the chain of frames from A to B through
        their closest common ancestor, each link's age, rate and broadcaster, and
        ``lookup_transform(A, B, latest)`` (B's pose in A: translation in metres,
        quaternion x y z w, roll pitch yaw in radians about fixed x, y, z) or tf2's
        message when it fails; the chain's links are drawn over the scene in
        :data:`CHAIN_COLOUR`. Called by :meth:`draw` (the caller holds the lock)."""
        a, b = self.pair_choice
        segments: list[list[tuple[float, float, float]]] = []
        if a is None or b is None or core is None:
            value = "<p>pick two frames</p>" if a is None or b is None else ""
        else:
            value, chain = self._pair_text(scene, core, a, b, stats, rates)
            poses = {f.frame_id: f.pose for f in scene.frames}
            for child, parent in chain:
                pc, pp = poses.get(child), poses.get(parent)
                if pc is not None and pp is not None:
                    segments.append([_xyz(pc), _xyz(pp)])
        colours = [[CHAIN_COLOUR, CHAIN_COLOUR] for _ in segments]
        self.chain, self.chain_count = self._segments(
            "/chain", self.chain, self.chain_count, segments, colours, 6.0)
        if value != self.pair_html:
            self.pair_html = value
            self.pair.content = value

    def _pair_text(self, scene: Scene, core: BufferCore, a: str, b: str,
                   stats: TfSummary | None, rates: Mapping[str, float] | None
                   ) -> tuple[str, list[tuple[str, str]]]:
        """The pair panel's HTML and the chain's links (child, parent), in the chain's
        order (:func:`tfbus.core.frame_path`, tfbus's one frame path)."""
        from transforms3d.euler import quat2euler

        parents = {f.frame_id: f.parent for f in scene.frames if f.parent is not None}
        names = frame_path(parents, a, b)
        links: list[tuple[str, str]] = []
        lines = []
        if names is not None:
            # each step up is the link (child, its parent); each step down the reverse
            links = [(x, y) if parents.get(x) == y else (y, x)
                     for x, y in itertools.pairwise(names)]
            lines.append("chain: " + " &rarr; ".join(_h(n) for n in names))
            views = {f.frame_id: f for f in scene.frames}
            for child, parent in links:
                fv = views.get(child)
                fs = stats.frames.get(child) if stats is not None else None
                rate = (rates or {}).get(child, fs.rate if fs is not None else 0.0)
                static = fv is not None and fv.static
                age = "" if fv is None or fv.age is None else f", age {fv.age:.2f} s"
                hz = "static" if static else f"{rate:.1f} Hz"
                who = fs.authority if fs is not None else (fv.authority if fv else "") or ""
                lines.append(f"&nbsp;&nbsp;{_h(parent)} &rarr; {_h(child)}: {hz}{age}, "
                             f"{_h(who)}")
        out = core.try_lookup_transform(a, b, Time(0))
        if isinstance(out, TransformStamped):
            v, q = out.transform.translation, out.transform.rotation
            roll, pitch, yaw = quat2euler((q.w, q.x, q.y, q.z), "sxyz")
            lines.append(f"{_h(b)} in {_h(a)}: translation [{v.x:.3f}, {v.y:.3f}, {v.z:.3f}] m"
                         f"<br>rotation (x y z w) [{q.x:.3f}, {q.y:.3f}, {q.z:.3f}, {q.w:.3f}]"
                         f"<br>roll pitch yaw [{roll:.3f}, {pitch:.3f}, {yaw:.3f}] rad")
        else:
            lines.append(f"lookup_transform({_h(a)}, {_h(b)}): {_h(out)}")
        return ("<p class='tfbus-pair' style='font-size:0.8em'>" + "<br>".join(lines)
                + "</p>"), links

    def set_visuals(self, visuals: Sequence[LinkVisual]) -> None:
        """Link geometry (``--urdf``) to draw on each link's frame once it is drawn: a
        child node of the frame, at the visual's origin, so it moves with the frame."""
        with self._lock:
            for v in visuals:
                self._pending_visuals.setdefault(v.link, []).append(v)

    def set_notes(self, notes: Sequence[str]) -> None:
        """Lines under the frame tree (a URDF mesh not found or unreadable), as text."""
        with self._lock:
            value = "".join(f"<p>{_h(n)}</p>" for n in notes)
            if value != self.notes_html:
                self.notes_html = value
                self.notes.content = value

    def set_findings(self, findings: Sequence[Finding] | None, note: str = "") -> None:
        """List ``tfbus doctor``'s findings in the page's "tf doctor" folder: per finding its
        level, check, message, frames, senders and advice (every field as text: ids are
        escaped as in the frame tree), the most severe first as
        :meth:`~tfbus.doctor.Doctor.report` orders them, at most
        :data:`MAX_FINDINGS_SHOWN`; ``note`` is a line above them (what was diagnosed).
        ``None``: no diagnosis (the panel is empty); ``[]``: "no findings"."""
        if findings is None:
            value = ""
        else:
            items = []
            for f in findings[:MAX_FINDINGS_SHOWN]:
                level = str(f.level)
                colour = _LEVEL_COLOURS.get(level, "inherit")
                who = (f"<br>frames: {', '.join(_h(x) for x in f.frames)}" if f.frames else "")
                who += (f"<br>senders: {', '.join(_h(x) for x in f.senders)}"
                        if f.senders else "")
                advice = f"<br><i>{_h(f.advice)}</i>" if f.advice else ""
                items.append(
                    f"<li class='tfbus-finding'><b style='color:{colour}'>{_h(level)}</b> "
                    f"<code>{_h(f.check)}</code>: {_h(f.message)}{who}{advice}</li>")
            more = len(findings) - MAX_FINDINGS_SHOWN
            value = (
                (f"<p>{_h(note)}</p>" if note else "")
                + (f"<ul style='font-size:0.75em;padding-left:1.2em'>{''.join(items)}</ul>"
                   if items else "<p>no findings</p>")
                + (f"<p>and {more} more</p>" if more > 0 else ""))
        with self._lock:
            self.graph.findings = tuple(findings or ())
            if value != self.findings_html:
                self.findings_html = value
                self.findings.content = value

    def _add_frame(self, frame_id: str) -> DrawnFrame:
        """The scene nodes of a frame seen for the first time: a frame node (parent of its
        ``--urdf`` geometry) and a label, both named by number, never by id."""
        scene_api = self.server.scene
        n = len(self.frames)
        node = scene_api.add_frame(f"/tf/f{n}", show_axes=False)
        label = scene_api.add_label(f"/tf/l{n}", text(frame_id))
        posed = self._attach(frame_id, f"/tf/f{n}")
        record = DrawnFrame(node, label, posed)
        self.frames[frame_id] = record
        self.labels[frame_id] = label
        return record

    def _attach(self, frame_id: str, node: str) -> bool:
        scene_api = self.server.scene
        for k, v in enumerate(self._pending_visuals.pop(frame_id, [])):
            name = f"{node}/v{k}"
            if v.kind == "box":
                h = scene_api.add_box(name, color=v.rgb, dimensions=v.size,
                                      position=v.xyz, wxyz=v.wxyz)
            elif v.kind == "cylinder":
                h = scene_api.add_cylinder(name, radius=v.size[0], height=v.size[1],
                                           color=v.rgb, position=v.xyz, wxyz=v.wxyz)
            elif v.kind == "mesh" and v.vertices is not None and v.faces is not None:
                h = scene_api.add_mesh_simple(name, v.vertices, v.faces, color=v.rgb,
                                              position=v.xyz, wxyz=v.wxyz)
            else:
                h = scene_api.add_icosphere(name, radius=v.size[0], color=v.rgb,
                                            position=v.xyz, wxyz=v.wxyz)
            self.visuals.setdefault(frame_id, []).append(h)
        return frame_id in self.visuals

    def aim(self, scene: Scene) -> None:
        """Point the browsers' initial camera at the drawn frames (their bounding box seen
        from the -x -y +z diagonal); nothing before a frame is placed."""
        placed = [_xyz(f.pose) for f in scene.frames if f.visible and f.pose is not None]
        if not placed:
            return
        pts = np.asarray(placed, dtype=np.float64)
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        centre = (lo + hi) / 2.0
        size = max(float(np.max(hi - lo)), 1.0)
        cam = self.server.initial_camera
        cam.look_at = tuple(centre)
        cam.position = tuple(centre + np.array([-0.9, -0.9, 0.8]) * size)
        self.camera_set = True

    def _segments(self, name: str, handle: Any, count: int,
                  segments: (list[list[tuple[float, float, float]]] | npt.NDArray[np.float64]
                             | npt.NDArray[np.float32]),
                  colours: Sequence[Sequence[tuple[int, int, int]]] | npt.NDArray[np.uint8],
                  thickness: float) -> tuple[Any, int]:
        """Show ``segments`` (``(N, 2, 3)``: each segment's two ends, metres in the fixed
        frame; sent as float32) in ``colours`` (``(N, 2, 3)`` sRGB 0-255) as the
        line-segments node ``name`` (re-made when their number changes, else updated in
        place; hidden when there are none; nothing sent when points and colours are those
        already shown)."""
        if len(segments) == 0:
            if handle is not None:
                handle.visible = False
            return handle, count
        pts = np.asarray(segments, dtype=np.float32)
        srgb = np.asarray(colours, dtype=np.uint8)
        sent = self._segments_sent.get(name)
        same_count = handle is not None and len(segments) == count
        same_pts = same_cols = False
        if same_count and sent is not None and handle.visible:
            same_pts = np.array_equal(sent[0], pts)
            same_cols = np.array_equal(sent[1], srgb)
            if same_pts and same_cols:
                return handle, count  # what the browser shows already: nothing sent
        # the colours as sent (linear), converted again only when they changed
        cols = sent[2] if same_cols and sent is not None else _to_linear(srgb)
        self._segments_sent[name] = (pts, srgb, cols)
        if handle is None or not same_count:
            if handle is not None:
                handle.remove()
            handle = self.server.scene.add_line_segments(
                name, pts, cols, thickness=thickness, thickness_units="screen")
        else:  # only what changed is given to viser (whose setters compare again)
            if not same_pts:
                handle.points = pts
            if not same_cols:
                handle.colors = cols
            handle.visible = True
        return handle, len(segments)

    def axes_colours(self, frame_id: str) -> tuple[tuple[int, int, int], ...] | None:
        """The colours (sRGB 0-255, as shown) of ``frame_id``'s x, y, z axes as last
        drawn; ``None`` when the frame is not drawn (hidden, unplaced). The scene node
        (:attr:`axes` ``.colors``) holds them as viser's linear values."""
        row = self.axes_rows.get(frame_id)
        if row is None or self.axes is None or not self.axes.visible:
            return None
        return tuple((int(c[0, 0]), int(c[0, 1]), int(c[0, 2]))
                     for c in self._axes_srgb[row:row + 3])

    def _draw_panel(self, scene: Scene, stats: TfSummary | None,
                    rates: Mapping[str, float] | None) -> None:
        rows = []
        hidden = 0
        for f in scene.frames:
            if not self.shown(f.frame_id):
                hidden += 1
                continue
            fs = stats.frames.get(f.frame_id) if stats is not None else None
            rate = (rates or {}).get(f.frame_id, fs.rate if fs is not None else 0.0)
            who = fs.authority if fs is not None else (f.authority or "")
            if f.static:
                state = "static"
            elif f.pose is None:
                state = "unplaced"
            elif f.colour is None:
                state = "hidden (timed out)"
            elif f.colour < 1.0:
                state = "stale"
            else:
                state = "ok"
            age = "" if f.age is None else f"{f.age:.1f} s"
            # a static link has no rate; a root frame is no link at all
            hz = "static" if f.static else "" if f.parent is None else f"{rate:.1f}"
            rows.append(
                f"<tr><td>{_h(f.frame_id)}</td><td>{_h(f.parent or '')}</td>"
                f"<td>{hz}</td><td>{age}</td><td>{state}</td><td>{_h(who)}</td></tr>"
            )
        errors = [f"<li>{_h(f.frame_id)}: {_h(f.error)}</li>" for f in scene.frames
                  if f.error is not None and self.shown(f.frame_id)]
        value = (
            f"<div style='{_PANEL_BOX}'><table style='{_PANEL_TABLE}'><tr><th>frame</th>"
            "<th>parent</th><th>Hz</th><th>age</th><th>state</th><th>broadcaster</th></tr>"
            + "".join(rows) + "</table></div>"
            + (f"<p>{hidden} of {len(scene.frames)} frames left out by the filter</p>"
               if hidden else "")
            + (f"<p>cannot place in [{_h(scene.fixed_frame)}]:</p><ul>{''.join(errors)}</ul>"
               if errors else "")
        )
        if value != self.panel_html:
            self.panel_html = value
            self.tree.content = value

    def draw_points(self, key: str, points: npt.NDArray[np.float32] | None,
                    colour: tuple[int, int, int] = (20, 90, 230)) -> None:
        """Draw ``points`` (``(N, 3)`` metres in the fixed frame) as the cloud ``key``
        (one per scan topic); ``None`` hides it."""
        with self._lock:
            handle = self.clouds.get(key)
            if points is None:
                if handle is not None:
                    handle.visible = False
                return
            pts = np.ascontiguousarray(points, dtype=np.float32).reshape(-1, 3)
            if handle is None:
                handle = self.server.scene.add_point_cloud(
                    f"/scans/s{len(self.clouds)}", pts, colour, point_size=0.03,
                    precision="float32")  # viser would send float16 (mm-level error)
                self.clouds[key] = handle
            else:
                handle.points = pts
                handle.visible = True

    def close(self) -> None:
        """Stop the server (closes its port)."""
        from tfbus.view import guard

        self.graph.close()
        self.server.stop()
        guard.unregister(self.guard)

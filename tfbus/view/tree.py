"""The browsable frame tree of ``tfbus view``'s page: every frame nested under its parent,
each with a show/hide checkbox, as rviz's TF display lists its "Frames" and "Tree".

The tree is rooted at the root of the fixed frame's tree (the fixed frame picked in the
page, else the scene's own), then the other trees of the buffer, each root first and the
children of a frame sorted by id (:func:`tree_rows`). A frame with children is a GUI folder
(its id) holding its own checkbox and then its children; a leaf is a checkbox. Unticking
a frame hides its axes and label (:attr:`FrameTree.hidden`, read by the page's drawing);
its children stay unless unticked too. What is unticked is kept by frame id, across
redraws, re-rooting and frames that come and go.

The GUI holds at most :data:`MAX_TREE_ROWS` frames (a tree of 10 000 frames does not make
10 000 GUI elements): the rest are counted in one line ("N more frames not listed"), and
the page's frame filter narrows the tree to the matching frames and their ancestors.
Ids are labels (viser draws them as text), control characters shown as escapes
(:func:`tfbus.view.escape.text`). The GUI is rebuilt only when the rows change.
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from tfbus.view.escape import text
from tfbus.view.scene import Scene

__all__ = ["MAX_HIDDEN", "MAX_TREE_ROWS", "FrameTree", "TreeRow", "descendants", "tree_rows"]

MAX_TREE_ROWS = 200
"""Frames listed in the page's tree at most; the rest are counted in one line."""
MAX_HIDDEN = 10_000
"""Frames that may be unticked at once (a page cannot grow the server's memory without
bound); a frame unticked beyond that stays shown."""


@dataclass(frozen=True, slots=True)
class TreeRow:
    """One frame of the tree as listed: its id, its depth (0: a root) and how many of its
    children are listed under it."""

    frame_id: str
    depth: int
    children: int


def descendants(parents: Mapping[str, str], frames: Iterable[str]
                ) -> dict[str, list[tuple[str, int]]]:
    """Each root's tree in depth-first order, ``(frame, depth)`` pairs starting with the
    root itself (children sorted by id), roots sorted by id; frames in a loop (no root
    reaches them) are in no tree."""
    names = list(dict.fromkeys([*frames, *parents.values()]))
    children: dict[str, list[str]] = {}
    for child, parent in parents.items():
        children.setdefault(parent, []).append(child)
    for kids in children.values():
        kids.sort()
    out: dict[str, list[tuple[str, int]]] = {}
    for root in sorted(n for n in names if n not in parents):
        order: list[tuple[str, int]] = []
        stack = [(root, 0)]
        while stack:
            name, depth = stack.pop()
            order.append((name, depth))
            stack.extend((c, depth + 1) for c in reversed(children.get(name, ())))
        out[root] = order
    return out


def tree_rows(parents: Mapping[str, str], frames: Iterable[str], *,
              fixed_frame: str | None = None, keep: Callable[[str], bool] | None = None,
              limit: int = MAX_TREE_ROWS) -> tuple[list[TreeRow], int]:
    """The frames as a depth-first listing (:func:`descendants`): the tree of
    ``fixed_frame``'s root first, then the other roots, children sorted by id; frames in
    a loop (no root) last, at depth 0.

    Args:
        parents: each child's parent (a root has no entry).
        frames: every frame id (roots included).
        fixed_frame: the frame whose tree is listed first.
        keep: which frames to list (with the ancestors of each, so that it stays nested
            under them); None: all.
        limit: rows at most.

    Returns:
        The rows (at most ``limit``) and how many frames were left out by the limit.
    """
    names = list(dict.fromkeys([*frames, *parents.values()]))
    trees = descendants(parents, names)
    roots = list(trees)
    for root, order in trees.items():
        if fixed_frame is not None and any(n == fixed_frame for n, _ in order):
            roots.remove(root)
            roots.insert(0, root)
            break
    entries = [e for root in roots for e in trees[root]]
    in_trees = {n for n, _ in entries}
    entries += [(n, 0) for n in names if n not in in_trees]  # in a loop
    listed: set[str] | None = None
    if keep is not None:  # kept, or the parent of a listed frame (children come later)
        listed = set()
        marked: set[str] = set()
        for name, _ in reversed(entries):
            if name in marked or keep(name):
                listed.add(name)
                parent = parents.get(name)
                if parent is not None:
                    marked.add(parent)
    kept = entries if listed is None else [e for e in entries if e[0] in listed]
    total = len(kept)
    kept = kept[:limit]
    shown = {n for n, _ in kept}
    counts: dict[str, int] = {}
    for n in shown:
        parent = parents.get(n)
        if parent is not None and parent in shown and n in in_trees:
            counts[parent] = counts.get(parent, 0) + 1
    rows = [TreeRow(n, d, counts.get(n, 0)) for n, d in kept]
    return rows, total - len(rows)


class FrameTree:
    """The page's "frame tree (show/hide)" folder (module doc). Made by
    :class:`~tfbus.view.server.TfPage`; :meth:`update` is called by each redraw, under
    the page's lock.

    Args:
        gui: the page's viser GUI (``server.gui``).
        lock: the page's lock (held by each redraw; a box's callback takes it).
        changed: called under ``lock`` when a box is ticked or unticked in the page (a
            paused bag is drawn again at once).
    """

    def __init__(self, gui: Any, lock: threading.Lock,
                 changed: Callable[[], None]) -> None:
        self._gui = gui
        self._lock = lock
        self._changed = changed
        self.folder: Any = gui.add_folder("frame tree (show/hide)")
        self.hidden: set[str] = set()
        """Frame ids unticked in the page (or by :meth:`set_shown`): not drawn."""
        self.rows: list[TreeRow] = []
        """The frames listed now, in the page's order."""
        self.more = 0
        """Frames not listed (beyond :data:`MAX_TREE_ROWS`)."""
        self.checkboxes: dict[str, Any] = {}
        """The checkbox of each listed frame id (``value``: shown)."""
        self.folders: dict[str, Any] = {}
        """The folder of each listed frame id that has listed children."""
        self.rebuilds = 0
        """Times the tree's GUI was made anew (its rows changed)."""
        self._handles: list[Any] = []
        self._key: tuple[Any, ...] | None = None
        self._inputs: tuple[Any, ...] | None = None

    def set_shown(self, frame_id: str, shown: bool) -> None:
        """Show or hide ``frame_id`` (as ticking its box does); drawn at the next redraw.
        At most :data:`MAX_HIDDEN` frames are hidden at once: beyond that a frame stays
        shown."""
        if shown:
            self.hidden.discard(frame_id)
        elif len(self.hidden) < MAX_HIDDEN:
            self.hidden.add(frame_id)
        box = self.checkboxes.get(frame_id)
        if box is not None and bool(box.value) != (frame_id not in self.hidden):
            box.value = frame_id not in self.hidden

    def _on_toggle(self, event: Any, frame_id: str) -> None:
        if event.client is None:  # our own write
            return
        with self._lock:
            box = self.checkboxes.get(frame_id)
            if box is None:
                return
            self.set_shown(frame_id, bool(box.value))
            self._changed()

    def update(self, scene: Scene, shown: Callable[[str], bool] | None = None,
               filter_key: object = None) -> None:
        """List ``scene``'s frames (module doc); ``shown`` is the page's frame filter and
        ``filter_key`` what it depends on (the compiled pattern). The rows are listed
        again only when the links, the fixed frame or the filter changed (10 000 frames
        take ~60 ms to list), the GUI made again only when the rows changed."""
        parents = {f.frame_id: f.parent for f in scene.frames if f.parent is not None}
        inputs = (parents, len(scene.frames), scene.fixed_frame, filter_key, shown is None)
        if inputs == self._inputs:
            return
        self._inputs = inputs
        rows, more = tree_rows(parents, (f.frame_id for f in scene.frames),
                               fixed_frame=scene.fixed_frame, keep=shown)
        key = (tuple(rows), more)
        if key == self._key:
            return
        self._key = key
        self.rows, self.more = rows, more
        for handle in self._handles:
            handle.remove()
        self._handles = []
        self.checkboxes = {}
        self.folders = {}
        self.rebuilds += 1
        gui = self._gui
        # an open folder per ancestor of the row being added: (depth, folder)
        open_folders: list[tuple[int, Any]] = []
        with self.folder:
            for row in rows:
                while open_folders and open_folders[-1][0] >= row.depth:
                    open_folders.pop()
                parent_folder = open_folders[-1][1] if open_folders else None
                label = text(row.frame_id)
                made = self._add(gui, parent_folder, row, label)
                if row.children:
                    open_folders.append((row.depth, made))
            if more:
                self._handles.append(gui.add_html(
                    f"<p class='tfbus-tree-more'>{more} more frames not listed "
                    f"(at most {MAX_TREE_ROWS}; the frame filter narrows the tree)</p>"))
            elif not rows:
                self._handles.append(gui.add_html("<p>no frames</p>"))

    def _add(self, gui: Any, parent_folder: Any, row: TreeRow, label: str) -> Any:
        """Add ``row``'s folder (with its own checkbox in it) or checkbox inside
        ``parent_folder`` (None: the tree's folder); the folder, else None."""
        def make() -> Any:
            folder = None
            if row.children:
                folder = gui.add_folder(label)
                self.folders[row.frame_id] = folder
                with folder:
                    box = self._checkbox(gui, row.frame_id, label)
            else:
                box = self._checkbox(gui, row.frame_id, label)
            if parent_folder is None:
                self._handles.append(folder if folder is not None else box)
            return folder

        if parent_folder is None:
            return make()
        with parent_folder:
            return make()

    def _checkbox(self, gui: Any, frame_id: str, label: str) -> Any:
        box = gui.add_checkbox(label, initial_value=frame_id not in self.hidden,
                               hint="shown: its axes and label are drawn")
        box.on_update(functools.partial(self._on_toggle, frame_id=frame_id))
        self.checkboxes[frame_id] = box
        return box

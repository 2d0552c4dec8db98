"""What one redraw of ``tfbus view`` sends to a browser (tfbus/view/server.py): only what
changed, one message per moved label, none for a frame at rest, none for hidden labels.
Counted from viser's own scene recording (``ViserServer.get_scene_serializer``: every
scene message queued for the browsers), against the known poses of 100 frames on a
circle."""

from __future__ import annotations

import math
from collections import Counter
from typing import Any

import pytest

pytest.importorskip("viser")

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.core import BufferCore
from tfbus.view import build_scene
from tfbus.view.server import TfPage

N = 100
STAMP = Time.from_sec(100.0)


def ring(core: BufferCore, turn: float) -> dict[str, tuple[float, float, float]]:
    """``N`` frames ``f0``.. children of ``world`` on a circle of radius 2 m, frame k at
    angle ``2 pi k / N + turn``, yawed by that angle, stamped ``STAMP`` + ``turn`` s;
    their positions."""
    stamp = Time.from_sec(STAMP.to_sec() + turn)
    where = {}
    for k in range(N):
        a = 2 * math.pi * k / N + turn
        xyz = (2.0 * math.cos(a), 2.0 * math.sin(a), 0.5)
        core.set_transform(TransformStamped(
            Header(stamp, "world"), f"f{k}",
            Transform(Vector3(*xyz), Quaternion(0.0, 0.0, math.sin(a / 2), math.cos(a / 2)))),
            "test")
        where[f"f{k}"] = xyz
    return where


class Sent:
    """The scene messages queued while inside (viser's recording of the scene)."""

    def __init__(self, page: TfPage) -> None:
        self.page = page
        self.messages: list[dict[str, Any]] = []

    def __enter__(self) -> Sent:
        self._rec: Any = self.page.server.get_scene_serializer()
        self._start = len(self._rec._messages)
        return self

    def __exit__(self, *exc: object) -> None:
        self.messages = [m for _, m in self._rec._messages[self._start:]]
        self._rec.serialize()  # ends the recording

    def kinds(self) -> Counter[str]:
        return Counter(str(m["type"]) for m in self.messages)

    def names(self, kind: str) -> list[str]:
        return [str(m["name"]) for m in self.messages if m["type"] == kind]


def draw(page: TfPage, core: BufferCore) -> None:
    """A redraw at the latest data, ages unknown (full colour: the colours never change)."""
    page.draw(build_scene(core), core=core)


def label_nodes(page: TfPage) -> set[str]:
    """The scene nodes of the moving frames' labels (not ``world``'s)."""
    return {str(h.name) for name, h in page.labels.items() if name != "world"}


def test_moving_frames_send_one_position_per_label_and_nothing_at_rest(page: TfPage) -> None:
    core = BufferCore(cache_time=10.0)
    ring(core, 0.0)
    draw(page, core)

    with Sent(page) as nothing:  # the same scene again: every node already shows it
        draw(page, core)
    assert nothing.messages == []

    where = ring(core, 0.1)  # every frame moved
    with Sent(page) as moved:
        draw(page, core)
    kinds = moved.kinds()
    # one position per label, no orientation (a label has none to show), no frame node
    # pose (no geometry hangs on them); the axes and the links: one node each
    assert kinds["SetPositionMessage"] == N
    assert set(moved.names("SetPositionMessage")) == label_nodes(page)
    assert kinds["SetOrientationMessage"] == 0
    assert sum(kinds.values()) <= N + 4, kinds
    for k in (0, 25, 99):
        label = page.labels[f"f{k}"]
        assert tuple(label.position) == pytest.approx(where[f"f{k}"], abs=1e-12)
        assert tuple(page.frames[f"f{k}"].position) == pytest.approx(where[f"f{k}"],
                                                                     abs=1e-12)
        a = 2 * math.pi * k / N + 0.1
        assert tuple(page.frames[f"f{k}"].wxyz) == pytest.approx(
            (math.cos(a / 2), 0.0, 0.0, math.sin(a / 2)), abs=1e-12)


def test_hidden_labels_cost_nothing_and_come_back_in_place(page: TfPage) -> None:
    core = BufferCore(cache_time=10.0)
    ring(core, 0.0)
    draw(page, core)
    page.labels_box.value = False
    with Sent(page) as hide:
        draw(page, core)
    # the labels of the N frames and of world are hidden, nothing else is sent
    assert hide.kinds() == Counter({"SetSceneNodeVisibilityMessage": N + 1})
    assert not any(h.visible for h in page.labels.values())

    where = ring(core, 0.3)
    with Sent(page) as moved:
        draw(page, core)
    kinds = moved.kinds()
    assert kinds["SetPositionMessage"] == 0 and kinds["SetOrientationMessage"] == 0
    assert sum(kinds.values()) <= 4, kinds  # the axes' and links' points

    page.labels_box.value = True
    with Sent(page) as shown:
        draw(page, core)
    # each label that moved while hidden is put where its frame is now, then shown
    assert shown.kinds()["SetPositionMessage"] == N
    assert set(shown.names("SetPositionMessage")) == label_nodes(page)
    assert shown.kinds()["SetSceneNodeVisibilityMessage"] == N + 1
    order = [(m["type"], m["name"]) for m in shown.messages]
    node = str(page.labels["f7"].name)
    assert order.index(("SetPositionMessage", node)) < \
        order.index(("SetSceneNodeVisibilityMessage", node))
    for k in (0, 7, 50):
        assert page.labels[f"f{k}"].visible
        assert tuple(page.labels[f"f{k}"].position) == pytest.approx(where[f"f{k}"],
                                                                     abs=1e-12)

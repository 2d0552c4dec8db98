"""``tfbus view --urdf``: link geometry from a URDF (the urdf tutorial's R2D2), attached to
each link's frame node at the visual's origin, so it follows RobotStatePublisher's
transforms."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

pytest.importorskip("viser")
pytest.importorskip("urdf_parser_py")

from tfbus import Time
from tfbus.core import BufferCore
from tfbus.messages import Header, JointState
from tfbus.robot_state import RobotStatePublisher
from tfbus.view import build_scene
from tfbus.view.robot import link_visuals
from tfbus.view.server import TfPage

URDF = (Path(__file__).resolve().parents[2] / "tests" / "data" / "urdf"
        / "urdf_tutorial_07-physics.urdf")
H = math.sin(1.57075 / 2)


def test_visuals_read_from_the_urdf() -> None:
    vis = link_visuals(URDF)
    base = [v for v in vis if v.link == "base_link"]
    assert [(v.kind, v.size) for v in base] == [("cylinder", (0.2, 0.6))]
    leg = next(v for v in vis if v.link == "right_leg")
    assert leg.kind == "box" and leg.size == (0.6, 0.1, 0.2)
    assert leg.xyz == (0.0, 0.0, -0.3)
    assert leg.wxyz == pytest.approx((math.cos(1.57075 / 2), 0.0, H, 0.0))
    assert base[0].rgb == (0, 0, 204)  # material "blue": rgba 0 0 .8 1
    assert {v.kind for v in vis} == {"box", "cylinder", "sphere"}
    with pytest.raises(ValueError, match="--urdf"):
        link_visuals(Path(__file__))


def test_visuals_follow_the_link_frames(page: TfPage) -> None:
    rsp = RobotStatePublisher(URDF)
    core = BufferCore()
    stamp = Time.from_sec(1.0)
    for t in rsp.static_transforms(stamp):
        core.set_transform_static(t, "rsp")
    joints = [j.name for j in rsp.model.joints if j.movable]
    js = JointState(header=Header(stamp, ""), name=joints, position=[0.3] * len(joints))
    for t in rsp.transforms(js):
        core.set_transform(t, "rsp")
    vis = link_visuals(URDF)
    page.set_visuals(vis)
    page.draw(build_scene(core, fixed_frame="base_link"))
    drawn = sum(len(h) for h in page.visuals.values())
    placed = {f for f in core.get_frame_names()}
    assert drawn == sum(1 for v in vis if v.link in placed) and drawn > 10
    for link, handles in page.visuals.items():
        node = page.frames[link].name
        mine = [v for v in vis if v.link == link]
        for h, v in zip(handles, mine, strict=True):
            assert h.name.startswith(node + "/")  # a child of the link's frame node
            assert tuple(h.position) == pytest.approx(v.xyz)
            assert tuple(h.wxyz) == pytest.approx(v.wxyz)

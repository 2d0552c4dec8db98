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
from tfbus.robot import RobotStatePublisher
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


MESH_URDF = """<robot name="meshy">
  <material name="red"><color rgba="1 0 0 1"/></material>
  <link name="base"><visual><geometry>
    <mesh filename="package://mypkg/meshes/box.stl" scale="0.5 0.5 0.5"/></geometry>
    <material name="red"/></visual></link>
  <link name="arm"><visual><origin xyz="0 0 0.5"/><geometry>
    <mesh filename="package://other/meshes/arm.obj"/></geometry></visual></link>
  <link name="cam"><visual><geometry>
    <mesh filename="file://{cam}"/></geometry></visual></link>
  <link name="rel"><visual><geometry><mesh filename="meshes/rel.dae"/></geometry></visual></link>
  <link name="gone"><visual><geometry>
    <mesh filename="package://nopkg/x.stl"/></geometry></visual></link>
  <link name="junk"><visual><geometry>
    <mesh filename="package://mypkg/meshes/junk.stl"/></geometry></visual></link>
  <joint name="j1" type="fixed"><parent link="base"/><child link="arm"/></joint>
  <joint name="j2" type="fixed"><parent link="base"/><child link="cam"/></joint>
  <joint name="j3" type="fixed"><parent link="base"/><child link="rel"/></joint>
  <joint name="j4" type="fixed"><parent link="base"/><child link="gone"/></joint>
  <joint name="j5" type="fixed"><parent link="base"/><child link="junk"/></joint>
</robot>
"""


def test_meshes_found_read_and_drawn(page: TfPage, tmp_path: Path,
                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """package:// above the URDF, in --mesh-dir and in ROS_PACKAGE_PATH; file:// and a
    path relative to the URDF; STL, OBJ and DAE (pycollada) read by trimesh and scaled;
    a mesh not found or unreadable is one note, never a crash."""
    import numpy as np
    import trimesh

    from tfbus import Header, Quaternion, Transform, TransformStamped, Vector3
    from tfbus.view.robot import load_robot

    box = trimesh.creation.box(extents=(1.0, 2.0, 3.0))  # 8 vertices at +-0.5, +-1, +-1.5
    pkg = tmp_path / "ws" / "mypkg"
    (pkg / "meshes").mkdir(parents=True)
    (pkg / "urdf" / "meshes").mkdir(parents=True)
    box.export(pkg / "meshes" / "box.stl")
    (pkg / "meshes" / "junk.stl").write_text("not a mesh")
    (tmp_path / "extra" / "other" / "meshes").mkdir(parents=True)
    box.export(tmp_path / "extra" / "other" / "meshes" / "arm.obj")
    box.export(tmp_path / "cam.stl")
    box.export(pkg / "urdf" / "meshes" / "rel.dae")
    urdf = pkg / "urdf" / "robot.urdf"
    urdf.write_text(MESH_URDF.format(cam=tmp_path / "cam.stl"))
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "nowhere"))

    robot = load_robot(urdf, [tmp_path / "extra"])
    by_link = {v.link: v for v in robot.visuals}
    assert sorted(by_link) == ["arm", "base", "cam", "rel"]
    assert {v.kind for v in robot.visuals} == {"mesh"}
    assert by_link["base"].source == pkg / "meshes" / "box.stl"          # above the URDF
    assert by_link["arm"].source == tmp_path / "extra" / "other" / "meshes" / "arm.obj"
    assert by_link["cam"].source == tmp_path / "cam.stl"                  # file://
    assert by_link["rel"].source == pkg / "urdf" / "meshes" / "rel.dae"   # relative
    base = by_link["base"]
    assert base.size == (0.5, 0.5, 0.5) and base.rgb == (255, 0, 0)  # scaled, material red
    assert base.vertices is not None and base.faces is not None and len(base.faces) == 12
    np.testing.assert_allclose(base.vertices.min(axis=0), [-0.25, -0.5, -0.75])
    np.testing.assert_allclose(base.vertices.max(axis=0), [0.25, 0.5, 0.75])
    for link in ("arm", "cam", "rel"):  # OBJ, STL, DAE: the same box, unscaled
        v = by_link[link].vertices
        assert v is not None
        np.testing.assert_allclose(v.max(axis=0), [0.5, 1.0, 1.5], atol=1e-6)
    assert by_link["arm"].xyz == (0.0, 0.0, 0.5)
    assert robot.notes == (
        f"gone: mesh package://nopkg/x.stl not found (looked in "
        f"{tmp_path / 'extra' / 'nopkg' / 'x.stl'}, {tmp_path / 'nowhere' / 'nopkg' / 'x.stl'}"
        "; --mesh-dir)",
        f"junk: mesh {pkg / 'meshes' / 'junk.stl'} cannot be read: no triangles in it",
    )
    # ROS_PACKAGE_PATH is searched too
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "extra"))
    assert {v.link for v in load_robot(urdf).visuals} == {"arm", "base", "cam", "rel"}

    page.set_visuals(robot.visuals)
    page.set_notes(robot.notes)
    core = BufferCore()
    for child in ("arm", "cam", "rel", "gone", "junk"):
        core.set_transform_static(TransformStamped(
            Header(Time(0), "base"), child,
            Transform(Vector3(1.0, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0))), "rsp")
    page.draw(build_scene(core, fixed_frame="base"))
    assert sorted(page.visuals) == ["arm", "base", "cam", "rel"]
    drawn = page.visuals["base"][0]
    assert drawn.name.startswith(page.frames["base"].name + "/")
    np.testing.assert_allclose(np.asarray(drawn.vertices), base.vertices)
    assert tuple(drawn.color) == (255, 0, 0)
    assert tuple(page.visuals["arm"][0].position) == (0.0, 0.0, 0.5)
    assert "gone: mesh package://nopkg/x.stl not found" in page.notes_html
    assert page.notes_html.count("<p>") == 2


def test_tutorial_meshes_missing_are_notes(monkeypatch: pytest.MonkeyPatch) -> None:
    """The R2D2 tutorial's gripper meshes (urdf_tutorial's .dae files) are not here:
    four notes, the other visuals drawn."""
    from tfbus.view.robot import load_robot

    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    robot = load_robot(URDF)
    assert len(robot.notes) == 4
    assert all(" not found (no --mesh-dir" in n and "urdf_tutorial/meshes/" in n
               for n in robot.notes)
    assert robot.notes[0] == (
        "left_gripper: mesh package://urdf_tutorial/meshes/l_finger.dae not found (no "
        "--mesh-dir, ROS_PACKAGE_PATH folder or folder named urdf_tutorial above the URDF "
        "to look in)")
    assert len(robot.visuals) == len(link_visuals(URDF)) > 10

"""Make docs/img/view_turtle.png and docs/img/view_r2d2.png: ``tfbus view``'s page in
Debian's headless Chromium (``scripts/install/install_chromium.sh``), 1280 x 720.

* the turtle bag (tests/data/webviz_turtle_tf_example.bag) at bag time 10.89 s;
* the urdf tutorial's R2D2 (tests/data/urdf/urdf_tutorial_07-physics.urdf) posed by
  RobotStatePublisher with every movable joint at 0.3, seen from base_link (its gripper
  meshes are not in the repository: the panel says so).

Everything is served on 127.0.0.1 at a free port; Chromium runs with a fresh profile and
a 60 s bound.

    .venv/bin/python scripts/docs/view_screenshots.py
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from tfbus import Time
from tfbus.cli._bag_source import BagSource
from tfbus.core import BufferCore
from tfbus.messages import Header, JointState
from tfbus.robot import RobotStatePublisher
from tfbus.view import build_scene
from tfbus.view.player import BagPlayer
from tfbus.view.robot import load_robot
from tfbus.view.server import TfPage
from tfbus.view.timeline import BagTimeline

ROOT = Path(__file__).resolve().parents[2]
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--window-size=1280,720", "--virtual-time-budget=8000", "--hide-scrollbars"]


def _ink(path: Path) -> int:
    from PIL import Image  # viser's own dependency (through imageio)

    grey = Image.open(path).convert("L")
    return sum(n for n, v in (grey.getcolors(maxcolors=1 << 16) or []) if v < 200)


def shoot(exe: str, page: TfPage, out: Path, tries: int = 5) -> None:
    """The most complete of ``tries`` screenshots (most dark pixels): viser fades its
    scene in after loading and a loaded machine can end Chromium's virtual-time budget
    before that is done."""
    best = -1
    with tempfile.TemporaryDirectory(prefix="tfbus-view-shot-") as tmp:
        for k in range(tries):
            shot = Path(tmp) / f"{k}.png"
            subprocess.run([exe, *FLAGS, f"--user-data-dir={tmp}/profile{k}",
                            f"--screenshot={shot}", f"http://127.0.0.1:{page.port}/"],
                           capture_output=True, timeout=60, check=True,
                           env={**os.environ, "TMPDIR": tmp})
            ink = _ink(shot)
            if ink > best:
                best = ink
                shutil.copyfile(shot, out)
    print(f"wrote {out.relative_to(ROOT)}")


def main() -> int:
    exe = shutil.which("chromium")
    if exe is None:
        print("Debian chromium is not installed (scripts/install/install_chromium.sh)",
              file=sys.stderr)
        return 2
    img = ROOT / "docs" / "img"
    page = TfPage("127.0.0.1", 0, title="tfbus view: tests/data/webviz_turtle_tf_example.bag")
    try:
        bag = ROOT / "tests" / "data" / "webviz_turtle_tf_example.bag"
        player = BagPlayer(page, BagTimeline.read(bag), paused=True,
                           summary=BagSource(bag).summary())
        player.seek(10.89)
        player.render()
        shoot(exe, page, img / "view_turtle.png")
    finally:
        page.close()

    urdf = ROOT / "tests" / "data" / "urdf" / "urdf_tutorial_07-physics.urdf"
    rsp = RobotStatePublisher(urdf)
    core = BufferCore()
    stamp = Time.from_sec(1.0)
    for t in rsp.static_transforms(stamp):
        core.set_transform_static(t, "robot_state_publisher")
    joints = [j.name for j in rsp.model.joints if j.movable]
    js = JointState(header=Header(stamp, ""), name=joints, position=[0.3] * len(joints))
    for t in rsp.transforms(js):
        core.set_transform(t, "robot_state_publisher")
    robot = load_robot(urdf)
    page = TfPage("127.0.0.1", 0, title=f"tfbus view --urdf {urdf.name}")
    try:
        page.set_visuals(robot.visuals)
        page.set_notes(robot.notes)
        page.draw(build_scene(core, fixed_frame="base_link"))
        shoot(exe, page, img / "view_r2d2.png")
    finally:
        page.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""tfbus in a Textual TUI: a live readout of base_link in odom, and a lookup on demand.

Run: ``python examples/textual_app.py`` (q quits, g looks up a frame nobody broadcasts).

* start-up: ``on_mount`` opens a session (:func:`tfbus.open_session`): Textual mounts and
  unmounts in different tasks, so the bus is held by the session's own task;
* a worker awaits the transform 0.1 s ahead, again and again; a timeout is shown in the
  status line, not raised;
* cancellation: Textual cancels the workers when the app exits;
* shutdown: ``on_unmount`` closes the session (``aclose()`` from the unmounting task).
"""

from __future__ import annotations

from typing import ClassVar

from textual import work
from textual.app import App, ComposeResult
from textual.widgets import Footer, Static

from tfbus import (
    Duration,
    Header,
    Quaternion,
    SystemClock,
    TimeoutException,
    Transform,
    TransformSession,
    TransformStamped,
    Vector3,
    every,
    open_session,
)


class FramesApp(App[None]):
    BINDINGS: ClassVar = [("q", "quit", "Quit"), ("g", "gripper", "Look up the gripper")]

    def compose(self) -> ComposeResult:
        yield Static("waiting for base_link...", id="pose")
        yield Static("", id="status")
        yield Footer()

    async def on_mount(self) -> None:
        self.clock = SystemClock()
        self.session: TransformSession = await open_session(clock=self.clock)
        self.odometry()
        self.follow()

    async def on_unmount(self) -> None:
        await self.session.aclose()

    @work(exclusive=False, group="robot")
    async def odometry(self) -> None:
        """Stands in for the robot: odom -> base_link at 50 Hz, 1 m/s along x."""
        start = self.clock.now()
        async for _ in every(0.02, clock=self.clock, immediate=True):
            now = self.clock.now()
            await self.session.broadcaster.send_transform(TransformStamped(
                Header(now, "odom"), "base_link",
                Transform(Vector3((now - start).to_sec(), 0.0, 0.0), Quaternion())))

    @work(exclusive=False, group="view")
    async def follow(self) -> None:
        """Await base_link 0.1 s ahead, show it, repeat."""
        pose = self.query_one("#pose", Static)
        while True:
            when = self.clock.now() + Duration.from_sec(0.1)
            try:
                t = await self.session.buffer.lookup_transform_async(
                    "odom", "base_link", when, timeout=1.0)
            except TimeoutException as exc:
                pose.update(f"no transform: {exc}")
                continue
            pose.update(f"base_link: x = {t.transform.translation.x:.2f} m")

    @work(exclusive=True, group="lookup")
    async def action_gripper(self) -> None:
        status = self.query_one("#status", Static)
        status.update("looking up gripper...")
        try:
            await self.session.buffer.lookup_transform_async(
                "odom", "gripper", self.clock.now(), timeout=0.5)
        except TimeoutException:
            known = self.session.buffer.frame_exists("gripper")
            status.update(f"gripper: no transform within 0.5 s (frame known: {known})")


if __name__ == "__main__":
    FramesApp().run()

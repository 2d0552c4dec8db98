# %% [markdown]
# # tfbus in a Jupyter notebook
# Each `# %%` block is one cell (VS Code, JupyterLab with jupytext). Every cell runs in its
# own task, so the bus is held by `open_session`'s background task, not by `async with`.

# %% setup: open the bus, buffer, listener and broadcasters (re-running it replaces them)
import asyncio

import anyio

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

# In-process here; pass a transport to reach a robot, e.g.
# open_session(ZenohTransport(config), name="robot") (see docs/recipes/zenoh.md).
tf = await open_session(name="robot")  # noqa: F704 (top-level await: a notebook cell)
clock = SystemClock()


async def odometry(session: TransformSession) -> None:
    """A simulated robot driving along x at 1 m/s, broadcasting odom -> base_link at 50 Hz
    on ``session`` (its own, not the global ``tf`` a re-run rebinds) until it is closed."""
    start = clock.now()
    try:
        async for _ in every(0.02, immediate=True):
            now = clock.now()
            x = (now - start).to_sec()
            await session.broadcaster.send_transform(TransformStamped(
                Header(now, "odom"), "base_link", Transform(Vector3(x, 0.0, 0.0), Quaternion())))
    except anyio.ClosedResourceError:
        pass  # its session was closed (the set-up cell re-run, or the close cell)


robot = asyncio.get_running_loop().create_task(odometry(tf))
print("session open:", tf)

# %% lookup: a time 0.2 s ahead: awaited until the broadcast covering it arrives
when = clock.now() + Duration.from_sec(0.2)
t = await tf.buffer.lookup_transform_async("odom", "base_link", when, timeout=2.0)  # noqa: F704
print(f"base_link at +0.2 s: x = {t.transform.translation.x:.2f} m")

# %% timeout: a frame nobody broadcasts: the timeout becomes a message, not a traceback
try:
    await tf.buffer.lookup_transform_async("odom", "gripper", clock.now(), timeout=0.5)  # noqa: F704
except TimeoutException as exc:
    print("no transform within 0.5 s:", exc)
print("gripper known to the buffer:", tf.buffer.frame_exists("gripper"))

# %% interrupt: a long wait you may interrupt (Kernel > Interrupt): the session stays open
print("waiting for map -> odom (interrupt me)", flush=True)
await tf.buffer.lookup_transform_async("map", "odom", clock.now(), timeout=600.0)  # noqa: F704

# %% after: an interruption leaves nothing left waiting, and the bus answering
print("pending waits:", tf.buffer.pending_waits, "closed:", tf.closed)
t = await tf.buffer.lookup_transform_async("odom", "base_link", clock.now(), timeout=2.0)  # noqa: F704
print(f"still live: x = {t.transform.translation.x:.2f} m")

# %% close: from this cell's task, though another cell's opened it
robot.cancel()
await tf.aclose()  # noqa: F704
print("closed:", tf.closed)

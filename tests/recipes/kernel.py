"""A real IPython kernel driven through jupyter_client, as a notebook front end drives it."""

from __future__ import annotations

import os
import queue
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]


@dataclass
class CellResult:
    """What one executed cell produced."""

    status: str  # "ok" or "error"
    stdout: str = ""
    ename: str = ""
    evalue: str = ""
    outputs: list[dict[str, Any]] = field(default_factory=list)


class Kernel:
    """Executes cells one at a time; every wait is bounded by ``timeout`` seconds."""

    def __init__(self, client: Any, manager: Any) -> None:
        self.client = client
        self.manager = manager

    def run(
        self, code: str, timeout: float = 60.0, interrupt_after: str | None = None
    ) -> CellResult:
        """Execute ``code``; with ``interrupt_after``, interrupt the kernel (SIGINT, as
        Kernel > Interrupt does) once that text has appeared on the cell's stdout."""
        msg_id = self.client.execute(code)
        result = CellResult(status="")
        deadline = time.monotonic() + timeout
        idle = False
        interrupted = False
        while not idle:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TimeoutError(f"cell did not finish within {timeout} s: {code[:80]!r}")
            try:
                msg = self.client.get_iopub_msg(timeout=min(remaining, 1.0))
            except queue.Empty:
                continue
            if msg["parent_header"].get("msg_id") != msg_id:
                continue
            kind, content = msg["msg_type"], msg["content"]
            if kind == "stream" and content["name"] == "stdout":
                result.stdout += content["text"]
                if interrupt_after and not interrupted and interrupt_after in result.stdout:
                    interrupted = True
                    self.manager.interrupt_kernel()
            elif kind == "error":
                result.ename, result.evalue = content["ename"], content["evalue"]
            elif kind in ("execute_result", "display_data"):
                result.outputs.append(content)
            elif kind == "status" and content["execution_state"] == "idle":
                idle = True
        while not result.status:
            reply = self.client.get_shell_msg(timeout=max(deadline - time.monotonic(), 1.0))
            if reply["parent_header"].get("msg_id") == msg_id:
                result.status = reply["content"]["status"]
        return result


@contextmanager
def ipykernel() -> Iterator[Kernel]:
    """Start an ipykernel on this interpreter with this worktree's tfbus; shut it down."""
    from jupyter_client.manager import KernelManager

    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    manager = KernelManager(kernel_name="python3")  # ipykernel's own: this interpreter
    manager.start_kernel(env=env, cwd=str(ROOT))
    client = manager.client()
    client.start_channels()
    try:
        client.wait_for_ready(timeout=60)
        yield Kernel(client, manager)
    finally:
        client.stop_channels()
        manager.shutdown_kernel(now=True)


def cells(path: Path) -> dict[str, str]:
    """The ``# %%`` cells of a percent-format script, keyed by their title's first word."""
    found: dict[str, str] = {}
    title = ""
    lines: list[str] = []
    for line in [*path.read_text().splitlines(), "# %% end"]:
        if line.startswith("# %%"):
            if title and not title.startswith("[markdown]"):
                found[title.split()[0].rstrip(":")] = "\n".join(lines)
            title, lines = line[4:].strip(), []
        else:
            lines.append(line)
    return found

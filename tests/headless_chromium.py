"""Debian's headless Chromium as a child process of a test: one run on a page with a
fresh profile (:func:`run_headless`), and the end of a browser a test started
(:func:`end_chromium`). Used by the documentation site's tests and the ``tfbus view``
tests (``tests/view/cdp.py`` drives a browser through CDP on top of them).

Chromium starts renderer and helper processes of its own, which may still be writing
into the profile after the browser process has gone: a ``TemporaryDirectory`` removed
at that moment fails (``Directory not empty``). Every browser here leads a session of its
own (``start_new_session=True``), its whole process group is ended by its PID, and the
profile's removal is retried for a bounded time. Everything is on 127.0.0.1.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import tempfile
import time
from typing import Any

__all__ = ["end_chromium", "run_headless"]


def end_chromium(proc: subprocess.Popen[Any] | None, profile: str, timeout: float) -> None:
    """End a Chromium we started with ``start_new_session=True`` and the processes it
    started (by its PID: the group it leads; a renderer left alive would go on writing
    into the profile), then remove its ``profile``: a helper still exiting may write into
    it after the browser has gone (``Directory not empty``), so the removal is retried
    for at most ``timeout`` seconds."""
    if proc is not None:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        if proc.poll() is None:
            proc.wait(timeout=timeout)
    deadline = time.monotonic() + timeout
    while True:
        try:
            shutil.rmtree(profile)
            return
        except FileNotFoundError:
            return
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.1)


def run_headless(exe: str, args: list[str], url: str, *, timeout: float = 60.0,
                 runs: int = 3, prefix: str = "tfbus-chromium-",
                 ) -> subprocess.CompletedProcess[bytes]:
    """``exe`` (headless Chromium) run on ``url`` with ``args`` and a fresh profile
    (``--user-data-dir``, also its ``TMPDIR``), to its end: its status and output. A run
    that outlives ``timeout`` seconds is ended and run again, at most ``runs`` times: on
    a loaded machine headless Chromium sometimes never ends its virtual-time budget (CI
    saw one such hang); a page that never loads still fails after the last. After each
    run the process group it leads is ended and its profile removed
    (:func:`end_chromium`).

    Raises:
        TimeoutError: no run ended within ``timeout`` seconds (its stderr's end in the
            message).
    """
    stuck = b""
    for _ in range(runs):
        profile = tempfile.mkdtemp(prefix=prefix)
        proc = subprocess.Popen([exe, *args, f"--user-data-dir={profile}", url],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                env={**os.environ, "TMPDIR": profile}, start_new_session=True)
        try:
            out, err = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            end_chromium(proc, profile, 30.0)
            stuck = proc.communicate(timeout=30.0)[1] or b""
            continue
        end_chromium(proc, profile, 30.0)
        return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)
    raise TimeoutError(f"chromium did not finish in {runs} runs of {timeout:g} s: "
                       f"{stuck[-2000:]!r}")

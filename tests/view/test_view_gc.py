"""``tfbus view`` serves with the garbage collector's young generation collected less often
(``tfbus.cli.view.young_gc_threshold``, ``YOUNG_GC_THRESHOLD``): raised only when lower,
never re-enabling a disabled collector, the older generations' thresholds kept, and the
thresholds found restored however the body ends; the command serves under it and gives
the process its thresholds back when it returns."""

from __future__ import annotations

import gc
import signal
from collections.abc import Iterator
from pathlib import Path

import pytest
from click.testing import CliRunner

pytest.importorskip("viser")

from tfbus.cli import cli
from tfbus.cli import view as view_cli
from tfbus.cli.view import YOUNG_GC_THRESHOLD, young_gc_threshold

TURTLE = Path(__file__).resolve().parents[2] / "tests" / "data" / "webviz_turtle_tf_example.bag"


@pytest.fixture(autouse=True)
def _thresholds() -> Iterator[None]:
    """The test's process gets its own thresholds back, whatever a test set."""
    before = gc.get_threshold()
    try:
        yield
    finally:
        gc.set_threshold(*before)


def test_a_lower_threshold_is_raised_for_the_body_and_restored() -> None:
    gc.set_threshold(700, 11, 12)
    with young_gc_threshold(5000):
        assert gc.get_threshold() == (5000, 11, 12)
    assert gc.get_threshold() == (700, 11, 12)


def test_a_higher_threshold_and_a_disabled_collector_are_left_as_they_are() -> None:
    for found in ((20_000, 10, 10), (5000, 3, 4), (0, 10, 10)):
        gc.set_threshold(*found)
        with young_gc_threshold(5000):
            assert gc.get_threshold() == found
        assert gc.get_threshold() == found


def test_an_exception_leaves_as_itself_with_the_thresholds_restored() -> None:
    gc.set_threshold(700, 10, 10)

    class Boom(Exception):
        pass

    with pytest.raises(Boom), young_gc_threshold(5000):
        assert gc.get_threshold() == (5000, 10, 10)
        raise Boom
    assert gc.get_threshold() == (700, 10, 10)


@pytest.fixture
def _signal_handlers() -> Iterator[None]:
    """The command installs its own SIGINT and SIGTERM handlers: the test's process gets
    its own back."""
    before = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in before.items():
            signal.signal(sig, handler)


@pytest.mark.usefixtures("_signal_handlers")
def test_the_view_command_serves_under_the_raised_threshold(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    gc.set_threshold(700, 10, 10)
    seen: list[tuple[int, int, int]] = []

    def serve(*_args: object, **_kwargs: object) -> None:
        seen.append(gc.get_threshold())

    monkeypatch.setattr(view_cli, "_serve_bag", serve)
    result = CliRunner().invoke(cli, ["view", "--bag", str(TURTLE), "--port", "0"])
    assert result.exit_code == 0, result.output
    assert seen == [(YOUNG_GC_THRESHOLD, 10, 10)]
    assert gc.get_threshold() == (700, 10, 10)

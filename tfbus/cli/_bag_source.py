"""Transforms from a recording: :class:`BagSource` (``--bag PATH``), loaded once through
:mod:`tfbus.bag`, and :func:`check_bag` (a one-line usage error for a file that is not a
bag of a known format).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from tfbus.cli._common import fail, one_line
from tfbus.cli._tf_source import TfSource

if TYPE_CHECKING:
    from tfbus.core import BufferCore
    from tfbus.monitor import TfSummary

__all__ = ["BagSource", "check_bag"]


def check_bag(path: Path) -> None:
    """A usage error (one line) unless ``path`` is a bag of a known format."""
    from tfbus.bag import BagError, detect_format

    try:
        detect_format(path)
    except BagError as err:
        fail(str(err))


class BagSource(TfSource):
    """Transforms from a bag file, loaded once (``tfbus.bag``)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.label = str(path)
        self._buffer: BufferCore | None = None
        self._summary: TfSummary | None = None
        self._problem: str | None = None
        self.chain: list[str] | None = None
        """``[source, target]``: the chain whose net delay :meth:`summary` measures
        (set it, then :meth:`reset_summary`)."""
        check_bag(path)

    def buffer(self) -> BufferCore:
        from tfbus.bag import BagReadError, load_buffer

        if self._buffer is None:
            try:
                self._buffer = load_buffer(self.path)
            except BagReadError as err:
                self._problem = one_line(str(err))
                self._buffer = err.partial
        assert self._buffer is not None
        return self._buffer

    def summary(self) -> TfSummary:
        from tfbus.bag import BagReadError, read_messages
        from tfbus.monitor import TfSummary

        if self._summary is None:
            stats = TfSummary()
            if self.chain is not None:
                stats.watch_chain(self.chain[0], self.chain[1])
            try:
                for rec in read_messages(self.path):
                    stats.add(rec.time, rec.message.transforms, rec.authority,
                              static=rec.is_static)
            except BagReadError as err:
                self._problem = one_line(str(err))
            self._summary = stats
        return self._summary

    def reset_summary(self) -> None:
        """Forget the summary: the next :meth:`summary` reads the bag again."""
        self._summary = None

    @property
    def problem(self) -> str | None:
        return self._problem

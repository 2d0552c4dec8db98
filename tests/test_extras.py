"""The install advice of a missing extra (:func:`tfbus._extras.extra_advice`, in every
MissingExtraError): ``pip install 'tfbus[EXTRA]'`` / ``pip install '.[EXTRA]'``, or, for a
tfbus installed editable from a clone (``make``'s ``.venv``), the ``pip install -e`` that
keeps it editable — a plain ``pip install '.[EXTRA]'`` there replaced the editable
install with a copy and compiled the core again. Read from PEP 610's
``direct_url.json``."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

import tfbus._extras
from tfbus._extras import editable_clone, extra_advice, missing_extra

CLONE = Path(tfbus._extras.__file__).resolve().parent.parent  # the tfbus imported here
PLAIN = "pip install 'tfbus[bag]' (from a clone of tfbus: pip install '.[bag]')"


class _Dist:
    def __init__(self, direct_url: str | None) -> None:
        self.direct_url = direct_url

    def read_text(self, name: str) -> str | None:
        assert name == "direct_url.json"
        return self.direct_url


def _installed(monkeypatch: pytest.MonkeyPatch, direct_url: object) -> None:
    text = direct_url if direct_url is None or isinstance(direct_url, str) else json.dumps(
        direct_url)
    monkeypatch.setattr(tfbus._extras.importlib.metadata, "distribution",
                        lambda name: _Dist(text) if name == "tfbus" else None)


def test_editable_from_this_clone_gives_the_editable_command(
    monkeypatch: pytest.MonkeyPatch
) -> None:
    _installed(monkeypatch, {"dir_info": {"editable": True}, "url": CLONE.as_uri()})
    assert editable_clone() == CLONE
    expected = (f"{sys.executable} -m pip install -e '{CLONE}[bag]' (tfbus is installed "
                f"editable from {CLONE}: -e keeps it so)")
    assert extra_advice("rosbags", "bag") == expected
    assert str(missing_extra("tfbus.bag", "rosbags", "bag")) == (
        f"tfbus.bag needs the 'rosbags' package: {expected}")


@pytest.mark.parametrize("direct_url", [
    {"dir_info": {}, "url": CLONE.as_uri()},  # pip install . (a copy)
    {"dir_info": {"editable": True}, "url": "file:///elsewhere/tfbus"},  # not this tfbus
    {"archive_info": {}, "url": "https://example.invalid/tfbus.tar.gz"},
    None,  # installed from an index: no direct_url.json
    "not json",
])
def test_otherwise_the_index_and_clone_commands(
    monkeypatch: pytest.MonkeyPatch, direct_url: object
) -> None:
    _installed(monkeypatch, direct_url)
    assert editable_clone() is None
    assert extra_advice("rosbags", "bag") == PLAIN

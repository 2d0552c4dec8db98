"""Ids as text in ``tfbus view``'s page: frame ids, broadcaster and robot names are
hostile input (a peer chooses them), shown as what they are and never as markup."""

from __future__ import annotations

import functools
import html
import re

__all__ = ["html_text", "text"]

_UNSAFE = re.compile(r"[\x00-\x1f\x7f-\x9f\u200e\u200f\u202a-\u202e\u2066-\u2069]")


def text(frame_id: object) -> str:
    """An id as visible text: control and bidirectional characters as ``\\xNN`` /
    ``\\uNNNN`` escapes (as ``tfbus`` prints them in a terminal)."""
    return _UNSAFE.sub(lambda m: f"\\x{ord(m.group()):02x}" if ord(m.group()) < 0x100
                       else f"\\u{ord(m.group()):04x}", str(frame_id))


def html_text(value: object) -> str:
    """:func:`text` of ``value`` escaped for HTML (:func:`html.escape`, quotes too)."""
    if isinstance(value, str):
        return _html_str(value)
    return html.escape(text(value), quote=True)


@functools.lru_cache(maxsize=8192)
def _html_str(value: str) -> str:
    """:func:`html_text` of a string, remembered (the panel writes each id on every
    redraw; bounded)."""
    return html.escape(text(value), quote=True)

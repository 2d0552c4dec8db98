"""Griffe extension for the API pages: docstrings written for Sphinx read well in Markdown.

tfbus' docstrings use reStructuredText roles and literals (``:class:`~tfbus.core.BufferCore```,
```` ``x`` ````, ``text::`` before a literal block, `` `text <url>`_ ``); mkdocstrings renders
Markdown. This rewrites them at load time, leaving the source untouched:

* ``:role:`~a.b.C``` -> `` `C` ``; ``:role:`a.b.C``` -> `` `a.b.C` `` (code, no link);
* `` `text <url>`_ `` -> ``[text](url)``;
* a line ending in ``::`` -> ``:`` (its indented block is a Markdown code block already).
"""

from __future__ import annotations

import re
from typing import Any

import griffe

_ROLE = re.compile(r":(?:py:)?(?:class|meth|func|mod|attr|exc|data|obj|const|ref):`(~?)([^`]+)`")
_LINK = re.compile(r"`([^`<]+?)\s*<([^>]+)>`__?")
_LITERAL_INTRO = re.compile(r"(?m)^(\s*)(.*?)\s*::\s*$")


def _role(match: re.Match[str]) -> str:
    tilde, target = match.groups()
    target = target.strip()
    if "<" in target and target.endswith(">"):  # :class:`text <target>`
        return f"`{target.split('<', 1)[0].strip()}`"
    shown = target.rsplit(".", 1)[-1] if tilde else target
    return f"`{shown}`"


def _intro(match: re.Match[str]) -> str:
    indent, text = match.groups()
    return f"{indent}{text}:" if text else ""


def convert(text: str) -> str:
    """Rewrite the reST constructs of ``text`` into Markdown."""
    text = _ROLE.sub(_role, text)
    text = _LINK.sub(r"[\1](\2)", text)
    return _LITERAL_INTRO.sub(_intro, text)


class SphinxRoles(griffe.Extension):
    """Rewrite every loaded object's docstring (see the module docstring)."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = convert(obj.docstring.value)

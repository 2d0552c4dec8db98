"""Griffe extension for the API pages: docstrings written for Sphinx read well in Markdown.

tfbus' docstrings use reStructuredText roles and literals (``:class:`~tfbus.core.BufferCore```,
```` ``x`` ````, ``text::`` before a literal block, `` `text <url>`_ ``); mkdocstrings renders
Markdown. This rewrites them at load time, leaving the source untouched:

* ``:role:`~a.b.C``` -> `` `C` ``; ``:role:`a.b.C``` -> `` `a.b.C` `` (code, no link);
* `` `text <url>`_ `` -> ``[text](url)``;
* a line ending in ``::`` -> ``:`` (its indented block is a Markdown code block already);
* Google-style sections written for readers, not for a parser: ``a, b: text`` in
  ``Args:`` becomes one entry per name; a ``Raises:`` entry whose exception names run
  over several lines is joined onto one; a ``Raises:`` section with no exception
  (``Nothing of its own ...``) becomes a sentence.
"""

from __future__ import annotations

import inspect
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


_SECTION = re.compile(r"^(\s*)(Args|Arguments|Parameters|Params|Raises|Exceptions):\s*$")
_NAMES = re.compile(r"^\*{0,2}[A-Za-z_]\w*(?:\s*,\s*\*{0,2}[A-Za-z_]\w*)+$")


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip())


def _fix_item(kind: str, item: list[str], pad: str) -> list[str]:
    head = item[0].strip()
    if kind == "raises":
        if ":" not in head:
            # names over several lines: join until the colon
            for k in range(1, len(item)):
                joined = " ".join(x.strip() for x in item[: k + 1])
                if ":" in joined:
                    return [pad + joined, *item[k + 1 :]]
            return []  # no exception named at all: handled by the caller
        return item
    names, sep, rest = head.partition(":")
    if sep and _NAMES.match(names.strip()):
        parts = [n.strip() for n in names.split(",")]
        out = [f"{pad}{parts[0]}:{rest}", *item[1:]]
        out += [f"{pad}{n}: As ``{parts[0]}``." for n in parts[1:]]
        return out
    return item


def _sections(text: str) -> str:
    lines = text.split("\n")
    out: list[str] = []
    i = 0
    while i < len(lines):
        m = _SECTION.match(lines[i])
        if not m:
            out.append(lines[i])
            i += 1
            continue
        base = len(m.group(1))
        kind = "raises" if m.group(2) in ("Raises", "Exceptions") else "args"
        j = i + 1
        body: list[str] = []
        while j < len(lines) and (not lines[j].strip() or _indent(lines[j]) > base):
            body.append(lines[j])
            j += 1
        while body and not body[-1].strip():
            body.pop()
        trailing = (j - i - 1) - len(body)
        items: list[list[str]] = []
        item_indent = min((_indent(x) for x in body if x.strip()), default=base + 4)
        for line in body:
            open_names = kind == "raises" and items and ":" not in " ".join(items[-1])
            if line.strip() and _indent(line) == item_indent and not open_names:
                items.append([line])
            elif items:
                items[-1].append(line)
        fixed: list[str] = []
        prose: list[str] = []
        for item in items:
            done = _fix_item(kind, item, " " * item_indent)
            if not done and kind == "raises":
                prose.append(" ".join(x.strip() for x in item))
            fixed.extend(done)
        if fixed:
            out.append(lines[i])
            out.extend(fixed)
        if prose:
            text_ = " ".join(prose)
            out.append(" " * base + "Raises: " + text_[0].lower() + text_[1:])
        out.extend([""] * trailing)
        i = j
    return "\n".join(out)


def convert(text: str) -> str:
    """Rewrite the reST constructs of ``text`` into Markdown."""
    text = _ROLE.sub(_role, text)
    text = _LINK.sub(r"[\1](\2)", text)
    text = _LITERAL_INTRO.sub(_intro, text)
    return _sections(text)


# Constants of the compiled core are found by inspection, and an int's "docstring" is
# int's own: not documentation of the constant.
_BUILTIN_DOCS = {
    inspect.cleandoc(t.__doc__ or "") for t in (int, float, str, bytes, tuple, frozenset)
}


class SphinxRoles(griffe.Extension):
    """Rewrite every loaded object's docstring (see the module docstring)."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is None:
            return
        if inspect.cleandoc(obj.docstring.value) in _BUILTIN_DOCS:
            obj.docstring = None
            return
        obj.docstring.value = convert(obj.docstring.value)

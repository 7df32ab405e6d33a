"""A griffe extension for the API reference (mkdocs.yml): Sphinx roles as Markdown.

The docstrings cite other code with reST roles (``:class:`~coolmuscle.chain.Chain```,
``:mod:`.expoly```, ``:meth:`Motion.first```), which mkdocstrings' Markdown shows
literally.  Each role becomes inline code of what it names, as Sphinx shows it: the
last part after a ``~``, the name otherwise (a leading ``.`` kept), ``()`` after a
function or method; double backquotes (reST inline literals) become single ones.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

_ROLE = re.compile(r":(?:py:)?(class|mod|func|meth|attr|data|exc|obj|const):`([^`]+)`")
_LITERAL = re.compile(r"``([^`]+)``")


def markdown(text: str) -> str:
    """``text`` with its Sphinx roles and reST literals as Markdown inline code."""
    def role(match: re.Match[str]) -> str:
        kind, target = match.group(1), match.group(2).strip()
        explicit = re.fullmatch(r"(.+?)\s*<(.+)>", target)     # :class:`text <target>`
        if explicit:
            return f"`{explicit.group(1)}`"
        shown = target.lstrip("~")
        if target.startswith("~"):
            shown = shown.rsplit(".", 1)[-1]
        if kind in ("func", "meth") and not shown.endswith(")"):
            shown += "()"
        return f"`{shown}`"
    return _LITERAL.sub(r"`\1`", _ROLE.sub(role, text))


class SphinxRoles(griffe.Extension):
    """Rewrites every docstring as it is loaded."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        del kwargs
        if obj.docstring is not None:
            obj.docstring.value = markdown(obj.docstring.value)

"""GitHub Actions workflow commands: ``::error file=F,line=L,col=C,title=T::message``.

A line in this form on a step's output becomes an annotation on the file and line in
the run's summary and in a pull request's diff (GitHub's "Workflow commands for GitHub
Actions": ``error``, ``warning`` and ``notice`` with ``file``, ``line``, ``col``,
``endLine``, ``endColumn`` and ``title``).  The message escapes ``%``, CR and LF; a
property value escapes ``:`` and ``,`` too, as the Actions toolkit does.
"""

from __future__ import annotations

from typing import Literal

__all__ = ["annotation", "escape_data", "escape_property"]

Level = Literal["error", "warning", "notice"]


def escape_data(text: str) -> str:
    """The message after ``::``: one line whatever it holds."""
    return text.replace("%", "%25").replace("\r", "%0D").replace("\n", "%0A")


def escape_property(text: str) -> str:
    """A property value (``file=``, ``title=``): no ``:`` or ``,`` left to end it."""
    return escape_data(text).replace(":", "%3A").replace(",", "%2C")


def annotation(level: Level, message: str, *, file: str | None = None,
               line: int | None = None, col: int | None = None,
               title: str | None = None) -> str:
    """One workflow command line (without its line end)."""
    props = [f"{key}={escape_property(str(value))}" for key, value in
             (("file", file), ("line", line), ("col", col), ("title", title))
             if value is not None]
    return f"::{level}{' ' + ','.join(props) if props else ''}::{escape_data(message)}"

"""What ``coolmuscle --version`` and ``coolmuscle version`` print: the version, and
whether the model's hot modules run compiled or as sources, and why
(:func:`coolmuscle._accel.describe`, docs/performance.md "Compiled hot modules").

Answered by :mod:`.entry` before the command-line library loads: two lines, at once.
"""

from __future__ import annotations

from ... import __version__, _accel


def version_text() -> str:
    """``coolmuscle 0.1.0`` and the hot modules' line, each ending in a newline."""
    return f"coolmuscle {__version__}\n{_accel.describe()}\n"

"""``python -m coolmuscle``: the same as the ``coolmuscle`` command (coolmuscle.tools.cli)."""

from __future__ import annotations

from .tools.cli import main

if __name__ == "__main__":
    main()

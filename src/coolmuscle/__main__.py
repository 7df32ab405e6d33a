"""``python -m coolmuscle``: the same as the ``coolmuscle`` command (coolmuscle.cli)."""

from __future__ import annotations

from .cli import main

if __name__ == "__main__":
    main()

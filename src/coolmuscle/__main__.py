"""``python -m coolmuscle``: the same as the ``coolmuscle`` command (coolmuscle.tools.entry)."""

from __future__ import annotations

from .tools.entry import main

if __name__ == "__main__":
    main()

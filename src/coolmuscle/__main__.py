"""``python -m coolmuscle``: the same as the ``coolmuscle`` command (coolmuscle.tools.entry).

The stop-signal handlers are installed before the command's modules load
(docs/reliability.md "signals").
"""

from __future__ import annotations

if __name__ == "__main__":
    from .tools.stopsignals import install_startup_handlers
    install_startup_handlers()
    from .tools.entry import main
    main()

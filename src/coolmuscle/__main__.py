"""``python -m coolmuscle``: the same as the ``coolmuscle`` command (coolmuscle.tools.cli.entry).

The stop-signal handlers are installed before the command's modules load
(docs/reliability.md "signals").
"""

from __future__ import annotations

if __name__ == "__main__":
    from .tools.cli.stopsignals import install_startup_handlers
    install_startup_handlers()
    from .tools.cli.entry import main
    main()

"""The ``coolmuscle`` command (docs/user-guide.md).

* :mod:`.entry` - the console script's first code: stop signals, then a quick ``run``;
* :mod:`.app` - the typer application: ``sim``, ``run`` and the other commands registered;
* :mod:`.run` - what ``coolmuscle run`` does, without the command-line library;
* :mod:`.host_commands` - ``check``, ``upload`` and ``term`` (typer definitions);
* :mod:`.version` - what ``--version`` prints: the version, compiled or the sources and why;
* :mod:`.exits`, :mod:`.stopsignals`, :mod:`.usage` - one-line errors, exit codes and stops.

Kept free of imports: the package loads before anything heavy (docs/reliability.md "signals").
"""

"""The everyday tools of a Cool Muscle user, as ``coolmuscle`` subcommands.

* :mod:`~coolmuscle.tools.check` - ``coolmuscle check``: the CML linter;
* :mod:`~coolmuscle.tools.upload` - ``coolmuscle upload``: send a file, verify by readback;
* :mod:`~coolmuscle.tools.term` - ``coolmuscle term``: the interactive terminal;
* :mod:`~coolmuscle.tools.commands` - their command-line definitions (typer).

They talk to motors only through :mod:`coolmuscle.client`.
"""

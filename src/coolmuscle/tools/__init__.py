"""The user's tools: the ``coolmuscle`` command and what observes a run, one sub-package a part.

* :mod:`.cli` - the ``coolmuscle`` command: its first code (``entry``), the typer
  application (``app``), ``coolmuscle run`` (``run``), exit codes and stop signals;
* :mod:`.script` - ``coolmuscle run`` scripts and golden transcripts (parse, run, check, record);
* :mod:`.check` - ``coolmuscle check``: the CML linter;
* :mod:`.trace` - the trace recorder of a chain (CSV, Parquet) and its plots;
* :mod:`.batch` - ``coolmuscle batch`` / ``sweep``: many runs on a process pool or Dask;
* :mod:`.term` - ``coolmuscle term`` and ``upload``: a terminal and a file sent to a motor;
* :mod:`.web` - ``--web``: the dashboard's host tools and a script played for the page;
* :mod:`.accel` - ``python -m coolmuscle.tools.accel``: the compiled hot modules.

The sub-packages import each other one way: ``cli`` registers the others' commands
(lazily) and they use ``cli.usage`` / ``cli.stopsignals``; ``check``, ``term`` talk to
motors only through :mod:`coolmuscle.client`.
"""

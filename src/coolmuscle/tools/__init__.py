"""The user's tools: the ``coolmuscle`` command and what observes a run.

* :mod:`.cli` - the ``coolmuscle`` command (``sim``, ``run``, ...);
* :mod:`.script` - ``coolmuscle run`` scripts and golden transcripts;
* :mod:`.trace` / :mod:`.plot` - the trace recorder of a chain (CSV, Parquet) and its plots;
* :mod:`.check` - ``coolmuscle check``: the CML linter;
* :mod:`.upload` - ``coolmuscle upload``: send a file, verify by readback;
* :mod:`.term` - ``coolmuscle term``: the interactive terminal;
* :mod:`.commands` - the command-line definitions of check/upload/term (typer).

``check``, ``upload`` and ``term`` talk to motors only through :mod:`coolmuscle.client`.
"""

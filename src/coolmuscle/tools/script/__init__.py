"""``coolmuscle run`` scripts and golden transcripts (docs/scripts.md).

* :mod:`.runner` - the format (command lines, ``<<`` replies, ``@`` directives) and its runner;
* :mod:`.record` - a run's transcript entries and the recorder of the bytes received
  (compiled, docs/performance.md);
* :mod:`.transcript` - a live session recorded as a golden transcript (``term``'s ``:log``).

The names most callers need are here: ``from coolmuscle.tools.script import run_script``.
"""

from __future__ import annotations

from .runner import (
                     DEFAULT_UNTIL_TIMEOUT,
                     RunResult,
                     Script,
                     ScriptError,
                     TranscriptEntry,
                     load_script,
                     parse_line,
                     parse_script,
                     run_script,
)

__all__ = ["DEFAULT_UNTIL_TIMEOUT", "RunResult", "Script", "ScriptError", "TranscriptEntry",
           "load_script", "parse_line", "parse_script", "run_script"]

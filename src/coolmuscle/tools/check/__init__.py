"""``coolmuscle check``: the CML linter (docs/user-guide.md "Check a CML file").

* :mod:`.lint` - the rules and :func:`check_program`;
* :mod:`.calls` - calls and jumps between banks;
* :mod:`.tree` - walking the CML tree (registers, RT3 steps, CM2 commands, columns);
* :mod:`.report` - rules, diagnostics, the per-file report;
* :mod:`.output` - the human and JSON forms (docs/check-schema.json).
"""

from __future__ import annotations

from .lint import RULES, BankSummary, CheckReport, Diagnostic, check_program

__all__ = ["RULES", "BankSummary", "CheckReport", "Diagnostic", "check_program"]

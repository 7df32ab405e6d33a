"""``coolmuscle capture``: a transparent relay that records a real motor's session
(docs/user-guide.md "coolmuscle capture").

* :mod:`.settings` - baud rate, parity, echo and firmware: given, or asked before the
  session (``?85``, ``K20``, ``K23``);
* :mod:`.ends` - the motor's port (any pyserial URL) and the host program's side
  (``--listen`` TCP, ``--pty`` pseudo-terminal);
* :mod:`.relay` - the two threads that pass every byte on as it arrives;
* :mod:`.recording` - the capture file: header, the session as a replayable script with
  ``# t=`` stamps (:class:`~coolmuscle.tools.script.transcript.SessionWriter`), end line;
* :mod:`.command` - the ``capture`` command.
"""

from __future__ import annotations

from .recording import CaptureFile, header_lines
from .settings import LineSettings

__all__ = ["CaptureFile", "LineSettings", "header_lines"]

"""Bank lines as they run: what a device tells an observer of its program and ladder banks.

Part of the device API beside :mod:`.api` (docs/device-api.md "Bank lines"): a client
that asks (:meth:`BankLineSource.observe_bank_lines`) is told of every line of a
program bank that starts (cml-users-guide.txt 2.2.2: a bank runs line by line) and of
every line a ladder or logic motion scan reaches (2.2.3, 4.5; RT3 3.5, 3.6).  Lines
joined by ``;`` run as one line (2.2.2 ";"), and a condition-only ladder line with the
line after it (6.4 ";"): such a run names its first and last stored line.

Nobody observes by default, and then the banks run exactly as without this: the test
plug-in's bank coverage (``pytest --cm-coverage``) and its failure messages ("the bank
line running then") are the clients.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable


@dataclass(frozen=True, slots=True)
class BankLine:
    """One bank line that ran: when, on which motor, which bank, which stored lines.

    ``first`` and ``last`` index the bank's stored lines from 0, as ``?#.n`` /
    ``?L#.n`` print them (6.6); they differ for lines joined by ``;``."""

    time: int          # kernel ns
    motor: int
    ladder: bool       # a ladder or logic motion bank (L#), else a program bank (B#)
    bank: int
    first: int
    last: int


BankLineListener = Callable[[BankLine], None]


@runtime_checkable
class BankLineSource(Protocol):
    """A device that tells of its bank lines (:class:`coolmuscle.chain.daisy.Chain`)."""

    def observe_bank_lines(self, listener: BankLineListener) -> Callable[[], None]:
        """Call ``listener`` with each :class:`BankLine` run from now on; returns the
        function that stops it (the last one gone, the banks run unobserved again)."""

"""Modes of operation 6060h / 6061h / 6502h (ethercat-bridge-users-guide.txt 6.2, chapter 6
intro, Appendix 3).

Pure rules, no I/O: which values name a mode, where an unknown value goes (6.2.2
note 3: the default csp mode), and which switches the chapter 6 diagram allows.
The diagram marks two switches "x: mode can not be transited, turn the power off
first"; read with the arrow counts of the flattened figure (CMD and CPIO are
reached from three modes, CML from three, csp from two, hm from one) they are CMD
to csp and CPIO to csp: csp is reached from hm and CML only, hm from csp only
(docs/fidelity.md "EtherCAT drive").
"""

from __future__ import annotations

from typing import Final

# Final: compiled code reads a constant in place, not from the module's dictionary.
HM: Final = 6
CSP: Final = 8
CML: Final = 101
CMD: Final = 120
CPIO: Final = 121
NAMES: Final = {HM: "hm", CSP: "csp", CML: "CML", CMD: "CMD", CPIO: "CPIO"}
POWER_UP: Final = CSP           # chapter 6 note 1: "always starts with csp mode (8)"

#: 6502h supported drive modes (6.2.1): bit 5 hm, bit 7 csp.
SUPPORTED_DRIVE_MODES: Final = (1 << 5) | (1 << 7)

#: 6.2.2 note 2: at least 5 ms between two switches.
SWITCH_INTERVAL_NS: Final = 5_000_000

#: target mode -> the modes it can be reached from (chapter 6 diagram).
_REACHED_FROM: Final[dict[int, frozenset[int]]] = {
    CSP: frozenset({HM, CML}),
    HM: frozenset({CSP}),
    CML: frozenset({CSP, CMD, CPIO}),
    CMD: frozenset({CSP, CML, CPIO}),
    CPIO: frozenset({CSP, CML, CMD}),
}


def resolve(value: int) -> int:
    """The mode a 6060h value selects: an unavailable one is csp (6.2.2 note 3)."""
    return value if value in NAMES else CSP


def allowed(current: int, target: int) -> bool:
    """Whether the chapter 6 diagram lets ``current`` switch to ``target``."""
    return target == current or current in _REACHED_FROM[target]


def needs_rest(target: int) -> bool:
    """Appendix 3: every switch but the one to CMD (3.4) starts "Confirm Motor is
    Inposition, Confirm No Error Occurs"."""
    return target != CMD


def is_cia402(mode: int) -> bool:
    """csp and hm (and CPIO, which is "CiA402 Position Control Mode", 7.1.1)."""
    return mode in (CSP, HM, CPIO)

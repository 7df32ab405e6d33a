"""Motor status Ux (cml-users-guide.txt 6.6 "?99") and K23 report selection (ch. 3 K23).

Ux values are added together when several apply.  While an alarm or the emergency
stop is latched, Ux shows that code alone (the motor is free or held; the manual
lists "1 position error overflow" etc. without adding 16) — docs/fidelity.md.
"""

from __future__ import annotations

from enum import IntFlag
from typing import Final


class Ux(IntFlag):
    """Status bits of ``Ux.n=`` (6.6 ?99)."""

    RUNNING = 0
    POSITION_ERROR_OVERFLOW = 1
    OVER_SPEED = 2              # over speed / regenerative voltage
    OVERLOAD = 4
    IN_POSITION = 8
    MOTOR_FREE = 16
    PUSH = 32                   # push motion (40 = 32 + 8: push completed)
    OVER_CURRENT = 64           # power module over current
    TEMPERATURE = 128
    PUSH_ERROR = 256
    EMERGENCY_STOP = 512


#: Alarm bits: each makes the motor free and raises the K34 alarm output (ch. 3 K56, K57).
ALARM_BITS: Final = (Ux.POSITION_ERROR_OVERFLOW | Ux.OVER_SPEED | Ux.OVERLOAD
                     | Ux.OVER_CURRENT | Ux.TEMPERATURE)


class Report(IntFlag):
    """K23 status report functions (ch. 3 K23)."""

    NONE = 0
    IN_POSITION_AND_ALARM = 1
    INPUT_CHANGE = 2
    OUTPUT_CHANGE = 4
    NO_ECHO = 8
    MESSAGES = 16


def status_line(motor_id: int, ux: int) -> str:
    """``Ux.1=8``."""
    return f"Ux.{motor_id}={int(ux)}"


def io_word_hex(word: int, bits: int) -> str:
    """Hex digits as in ``IN.1=1C`` / ``OUT.1=03`` (6.6 ?70, ?50): two digits."""
    del bits
    return f"{word & 0xFF:02X}"

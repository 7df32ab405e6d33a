"""The errors of the desk tools: each is a line a user can act on.

:class:`DeskError` is bad input (the command's exit status 2, docs/real-motor.md): no
motor on the port, a wrong baud rate, a backup of another firmware, a value out of
range in a backup, an unreadable file.  A restore that fails part-way is not an
exception but a :class:`~.restorer.RestoreReport` that says what was and was not
written.
"""

from __future__ import annotations

from ...errors import CoolMuscleError

__all__ = ["DeskError", "NoMotorError", "BackupFileError", "FirmwareMismatchError"]


class DeskError(CoolMuscleError, ValueError):
    """Input the desk tools cannot work with (exit status 2)."""


class NoMotorError(DeskError):
    """Nothing answers on the port (no motor, the wrong port, or the wrong baud rate)."""


class BackupFileError(DeskError):
    """A backup file that cannot be read or holds a line a motor would not take."""


class FirmwareMismatchError(DeskError):
    """A backup of another firmware than the motor it is to be restored to."""

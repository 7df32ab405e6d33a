"""The error of a command line that does not fit together (exit status 2)."""

from __future__ import annotations

from ...errors import CoolMuscleError


class UsageError(CoolMuscleError, ValueError):
    """Options that do not fit together (exit status 2)."""

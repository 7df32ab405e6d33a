"""Test-wide settings.

Hypothesis explores new random examples on every local run (and keeps the failures it
finds in .hypothesis/); under CI (``CI`` set) it draws a fixed sequence, so the suite is
the same every run there, as the rest of it is in virtual time.
"""

from __future__ import annotations

import os

from hypothesis import settings

settings.register_profile("ci", derandomize=True, database=None, print_blob=True)
if os.environ.get("CI"):
    settings.load_profile("ci")

"""Registers ``batch`` and ``sweep`` on the ``coolmuscle`` command (docs/batch.md)."""

from __future__ import annotations

import typer

from .command import batch
from .sweep import sweep

__all__ = ["register"]


def register(app: typer.Typer) -> None:
    """Add ``batch`` and ``sweep`` to the ``coolmuscle`` command."""
    app.command()(batch)
    app.command()(sweep)

"""Running ``coolmuscle ARGS`` in the test's own process (the typer app's ``main``)."""

from __future__ import annotations

import pytest

from coolmuscle.tools.cli.app import main


def cli(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    """Run ``coolmuscle ARGS`` in this process: (exit status, stdout, stderr)."""
    try:
        main(list(args))
        code = 0
    except SystemExit as exc:
        code = int(exc.code or 0)
    captured = capsys.readouterr()
    return code, captured.out, captured.err

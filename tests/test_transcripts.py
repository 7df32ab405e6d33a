"""Golden transcripts: exact bytes in and out for the manuals' examples (tests/transcripts/).

Each ``.cml`` file is a ``coolmuscle run`` script whose ``<<`` lines are the exact bytes
the motor must send (docs/scripts.md).  A header comment ``# chain: motors=N
firmware=NAME machine=FILE`` chooses the chain; the default is one CM2 motor.  A
machine file (docs/machine-file.md) is named relative to the transcript's directory
(``machine=machines/stopper.toml``).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from coolmuscle.chain.daisy import Chain
from coolmuscle.tools.script.runner import load_script, run_script

TRANSCRIPTS = Path(__file__).parent / "transcripts"
_CHAIN = re.compile(r"^# chain:(.*)$", re.MULTILINE)


def chain_options(text: str) -> dict[str, object]:
    """``# chain: motors=3 firmware=rt3`` -> Chain keyword arguments."""
    match = _CHAIN.search(text)
    options: dict[str, object] = {}
    if match:
        for item in match.group(1).split():
            key, _, value = item.partition("=")
            options[key] = int(value) if value.isdigit() else value
    return options


def transcript_files() -> list[Path]:
    return sorted(TRANSCRIPTS.glob("*.cml"))


@pytest.mark.parametrize("path", transcript_files(), ids=lambda p: p.stem)
def test_golden_transcript(path: Path, tmp_path: Path) -> None:
    text = path.read_text(encoding="utf-8")
    script = load_script(path)
    assert script.expectations > 0, f"{path.name} has no << expectations"
    options = chain_options(text)
    if options.pop("state", None):
        options["state_dir"] = tmp_path
    if "machine" in options:
        options["machine"] = path.parent / str(options["machine"])
    chain = Chain(**options)  # type: ignore[arg-type]
    try:
        result = run_script(script, chain)
    finally:
        chain.close()
    assert result.ok, result.summary() + "\n" + result.format()

"""The two header forms of a script (docs/scripts.md, docs/batch.md): ``# coolmuscle:``
(what ``run`` documents) and ``# chain:`` (the golden transcripts'); ``run`` and
``batch`` read both, so one file runs on the same chain in both."""

from __future__ import annotations

from pathlib import Path

import pytest

from coolmuscle.tools.batch.job import chain_header, execute, make_job
from coolmuscle.tools.cli.run import header_defaults

SCRIPT = "{header} motors=2 firmware=rt3\n?96.2\n<< ?96.2\\r\\nPx.2=0\\r\\n\n"


@pytest.mark.parametrize("header", ["# coolmuscle:", "# chain:", "# Chain:"])
def test_run_and_batch_read_either_header(header: str, tmp_path: Path) -> None:
    path = tmp_path / "two.cml"
    path.write_text(SCRIPT.format(header=header))
    assert header_defaults(path, None, None, None)[:2] == (2, "rt3")
    assert chain_header(path.read_text()) == {"motors": "2", "firmware": "rt3"}
    outcome = execute(make_job(str(path), path.read_text(), tmp_path))
    assert outcome.status == "pass", outcome.message


def test_a_later_header_line_adds_to_an_earlier_one() -> None:
    assert chain_header("# chain: motors=3\n# coolmuscle: firmware=cm1\n") == \
        {"motors": "3", "firmware": "cm1"}

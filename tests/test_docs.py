"""The documentation builds (mkdocs + mkdocstrings, ``--strict``) and its schema is valid."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import jsonschema

ROOT = Path(__file__).resolve().parents[1]


def test_mkdocs_builds_strict_with_the_api_reference(tmp_path: Path) -> None:
    site = tmp_path / "site"
    out = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict",
                          "--config-file", str(ROOT / "mkdocs.yml"), "--site-dir", str(site)],
                         capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert out.returncode == 0, out.stdout + out.stderr
    api = (site / "api" / "index.html").read_text(encoding="utf-8")
    for name in ("wait_in_position", "connect_async", "CoolMuscleTimeout", "check_program"):
        assert name in api
    # the docstrings' Sphinx roles are code, not literal ":class:`...`" text
    # (scripts/griffe_sphinx_roles.py)
    for page in site.rglob("*.html"):
        text = page.read_text(encoding="utf-8")
        assert not re.search(r":(class|mod|func|meth|attr|exc|data):`", text), page
    assert "<code>coolmuscle.client.sync</code>" in api
    guide = (site / "user-guide" / "index.html").read_text(encoding="utf-8")
    assert "coolmuscle check" in guide


def test_the_check_schema_is_a_valid_json_schema() -> None:
    schema = json.loads((ROOT / "docs" / "check-schema.json").read_text())
    jsonschema.Draft202012Validator.check_schema(schema)

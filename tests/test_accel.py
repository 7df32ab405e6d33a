"""The compiled hot modules (coolmuscle/_accel.py, docs/performance.md "Compiled hot
modules"): in use when current, never when stale, and giving the same bytes as the
sources.

Issue 18 ("the motion is unchanged: traces identical") and issue 12 item 9 ("the
motion identical to the exact model"): tests/accel_worker.py runs every example and
golden transcript with a 1 ms trace, a 4-axis csp stream and a 15-motor PTP bank, once
compiled and once with ``COOLMUSCLE_PURE=1``; the two digests must be equal line by line.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import coolmuscle._accel as accel
from coolmuscle.tools.accel import build as accel_tool

ROOT = Path(__file__).resolve().parents[1]
WORKER = Path(__file__).with_name("accel_worker.py")


def run_worker(pure: bool) -> subprocess.Popen[str]:
    env = dict(os.environ)
    env.pop("COOLMUSCLE_PURE", None)
    if pure:
        env["COOLMUSCLE_PURE"] = "1"
    return subprocess.Popen([sys.executable, str(WORKER), str(ROOT)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


@pytest.fixture(scope="module")
def built() -> None:
    """The compiled modules of these sources (scripts/test has built them: a no-op)."""
    assert accel_tool.build(quiet=True) == 0, "python -m coolmuscle.tools.accel build failed"


def test_a_fresh_process_imports_the_compiled_modules(built: None) -> None:
    code = ("import coolmuscle._accel as a, coolmuscle.motor.motion.dynamics as d, "
            "coolmuscle.sim.kernel as k; print(a.active(), d.__file__, k.__file__)")
    env = {k: v for k, v in os.environ.items() if k != "COOLMUSCLE_PURE"}
    active, *files = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                                    text=True, check=True).stdout.split()
    assert active == "True"
    assert all(f.endswith(".so") and "_compiled" in f for f in files), files


def test_compiled_and_pure_give_the_same_bytes_for_every_script_trace_and_stream(
        built: None) -> None:
    compiled, pure = run_worker(False), run_worker(True)
    out_c, err_c = compiled.communicate(timeout=300)
    out_p, err_p = pure.communicate(timeout=300)
    assert compiled.returncode == 0, err_c
    assert pure.returncode == 0, err_p
    head_c, *lines_c = out_c.splitlines()
    head_p, *lines_p = out_p.splitlines()
    assert json.loads(head_c)["compiled"] is True, head_c
    assert json.loads(head_p)["compiled"] is False, head_p
    assert len(lines_c) >= 80                  # every example and transcript, csp, bank
    for a, b in zip(lines_c, lines_p, strict=True):
        assert a == b


def test_a_pure_run_imports_the_sources() -> None:
    code = "import coolmuscle.motor.motion.dynamics as d; print(d.__file__)"
    env = dict(os.environ, COOLMUSCLE_PURE="1")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, check=True).stdout.strip()
    assert out.endswith("dynamics.py")


@pytest.fixture
def fake_build(built: None, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A copy of the real manifest in a temporary build directory."""
    manifest = json.loads(accel.MANIFEST.read_text(encoding="utf-8"))
    for rel in manifest["files"].values():
        dest = tmp_path / rel
        dest.parent.mkdir(parents=True, exist_ok=True)
        dest.write_bytes(b"")
    (tmp_path / "manifest.json").write_text(json.dumps(manifest), encoding="utf-8")
    monkeypatch.setattr(accel, "BUILD_DIR", tmp_path)
    monkeypatch.setattr(accel, "MANIFEST", tmp_path / "manifest.json")
    return tmp_path


def edit_manifest(build: Path, **changes: object) -> None:
    data = json.loads((build / "manifest.json").read_text(encoding="utf-8"))
    data.update(changes)
    (build / "manifest.json").write_text(json.dumps(data), encoding="utf-8")


def test_a_current_build_is_accepted(fake_build: Path) -> None:
    files, reason = accel._read_manifest()
    assert files is not None and set(files) >= set(accel.MODULES), reason


def test_an_edited_source_turns_the_whole_build_off(fake_build: Path) -> None:
    edit_manifest(fake_build, digest="0" * 64)
    files, reason = accel._read_manifest()
    assert files is None and "sources changed" in reason


@pytest.mark.parametrize("change, words", [
    ({"cache_tag": "cpython-399"}, "built for cpython-399"),
    ({"modules": ["coolmuscle.motor.motion.expoly"]}, "another module list"),
    ({"files": None}, "malformed"),
])
def test_a_build_for_something_else_is_refused(fake_build: Path, change: dict[str, object],
                                               words: str) -> None:
    edit_manifest(fake_build, **change)
    files, reason = accel._read_manifest()
    assert files is None and words in reason


def test_a_missing_or_damaged_build_is_refused(fake_build: Path) -> None:
    (fake_build / "manifest.json").write_text("{not json", encoding="utf-8")
    assert accel._read_manifest()[0] is None
    (fake_build / "manifest.json").unlink()
    files, reason = accel._read_manifest()
    assert files is None and "not built" in reason


def test_the_build_tool_answers_status_and_bad_usage(
        built: None, capsys: pytest.CaptureFixture[str]) -> None:
    assert accel_tool.main(["status"]) == 0
    assert "built from the current sources" in capsys.readouterr().out
    assert accel_tool.main(["build"]) == 0               # current: nothing to do
    assert "current" in capsys.readouterr().out
    assert accel_tool.main(["frobnicate"]) == 2
    assert accel_tool.main(["build", "--fast"]) == 2
    assert "unknown option --fast" in capsys.readouterr().err


@pytest.mark.parametrize("kind", [bytes, bytearray, memoryview])
def test_the_host_line_takes_any_byte_buffer_as_the_sources_did(kind: type) -> None:
    """A compiled function checks its argument types; the host line's entry points take
    bytes, bytearray and memoryview, as the sources always did (2.1 ``?96`` query)."""
    from coolmuscle.chain.daisy import Chain
    chain = Chain(motors=1)
    out: list[bytes] = []
    chain.host_line.add_listener(out.append)
    chain.host_line.feed(kind(b"?96.1\r"))
    chain.kernel.advance(10_000_000)
    assert b"".join(out).endswith(b"Px.1=0\r\n")


@pytest.mark.parametrize("until", [1.5e9, 2_000_000_000, 7.9])
def test_the_kernel_takes_float_times_and_floors_them(until: float) -> None:
    from coolmuscle.sim.kernel import Kernel
    kernel = Kernel(0.0)
    ran: list[int] = []
    kernel.schedule(until / 2, lambda: ran.append(kernel.now))
    kernel.run(until=until)
    assert kernel.now == int(until) and isinstance(kernel.now, int)
    assert ran == [int(until / 2)]


def test_a_build_without_mypy_says_so_and_keeps_the_sources(
        fake_build: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    import importlib.util
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "mypyc" else real(name, *a))
    assert accel_tool.main(["build", "--force"]) == 1
    assert "needs mypy" in capsys.readouterr().err
    assert (fake_build / "manifest.json").is_file()          # nothing removed


def test_a_read_only_install_gets_one_line_not_a_traceback(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(accel, "PACKAGE_DIR", tmp_path / "no" / "such" / "dir")
    assert accel_tool.main(["build"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("coolmuscle.tools.accel build: ") and "Traceback" not in err

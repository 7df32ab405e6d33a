"""The compiled hot modules (coolmuscle/_accel.py, docs/performance.md "Compiled hot
modules"): in use when current, never when stale, and giving the same bytes as the
sources; the build (coolmuscle/tools/accel/compiler.py) compiles, keeps the sources or
fails as ``COOLMUSCLE_COMPILE`` and the machine say.  tests/test_packaging.py builds and
installs real wheels.

The compiled code must not change the motion (traces identical, and the same as the
exact model): tests/accel_worker.py runs every example and
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
from coolmuscle.tools.accel import compiler

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
    """The compiled modules of these sources (the editable install compiled them: a no-op
    unless a hot module was edited since)."""
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
    manifest = json.loads((accel.BUILD_DIR / accel.MANIFEST_NAME).read_text(encoding="utf-8"))
    for rel in manifest["files"].values():
        dest = tmp_path / rel
        dest.parent.mkdir(parents=True, exist_ok=True)
        dest.write_bytes(b"")
    (tmp_path / "manifest.json").write_text(json.dumps(manifest), encoding="utf-8")
    monkeypatch.setattr(accel, "BUILD_DIR", tmp_path)
    return tmp_path


def edit_manifest(build: Path, **changes: object) -> None:
    data = json.loads((build / "manifest.json").read_text(encoding="utf-8"))
    data.update(changes)
    (build / "manifest.json").write_text(json.dumps(data), encoding="utf-8")


def test_a_current_build_is_accepted(fake_build: Path) -> None:
    files, reason = accel.read_manifest()
    assert files is not None and set(files) >= set(accel.MODULES), reason


def test_an_edited_source_turns_the_whole_build_off(fake_build: Path) -> None:
    edit_manifest(fake_build, digest="0" * 64)
    files, reason = accel.read_manifest()
    assert files is None and "a hot module changed since it was compiled" in reason


@pytest.mark.parametrize("change, words", [
    ({"cache_tag": "cpython-399"}, "compiled for cpython-399"),
    ({"modules": ["coolmuscle.motor.motion.expoly"]}, "another module list"),
    ({"files": None}, "malformed"),
])
def test_a_build_for_something_else_is_refused(fake_build: Path, change: dict[str, object],
                                               words: str) -> None:
    edit_manifest(fake_build, **change)
    files, reason = accel.read_manifest()
    assert files is None and words in reason


def test_a_missing_or_damaged_build_is_refused(fake_build: Path) -> None:
    (fake_build / "manifest.json").write_text("{not json", encoding="utf-8")
    assert accel.read_manifest()[0] is None
    (fake_build / "manifest.json").unlink()
    files, reason = accel.read_manifest()
    assert files is None and reason.startswith("not compiled; pip install again")


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


def test_a_forced_build_without_mypy_says_so_and_keeps_the_current_build(
        fake_build: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(compiler, "find_spec", lambda name: None)
    assert accel_tool.main(["build", "--force"]) == 1
    assert "no mypy (mypyc)" in capsys.readouterr().err
    assert accel.read_manifest()[0] is not None                # nothing removed


def test_a_read_only_install_gets_one_line_not_a_traceback(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(accel, "PACKAGE_DIR", tmp_path / "no" / "such" / "dir")
    assert accel_tool.main(["build"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("coolmuscle.tools.accel build: ") and "Traceback" not in err


# -- the build: compiled, the sources and why, or a failed build -----------------------
@pytest.fixture
def build_env(monkeypatch: pytest.MonkeyPatch) -> pytest.MonkeyPatch:
    """No COOLMUSCLE_COMPILE or CC of the caller's environment."""
    monkeypatch.delenv("COOLMUSCLE_COMPILE", raising=False)
    monkeypatch.delenv("CC", raising=False)
    return monkeypatch


def test_compile_0_keeps_the_sources_and_says_so(fake_build: Path,
                                                 build_env: pytest.MonkeyPatch) -> None:
    """The escape hatch: ``COOLMUSCLE_COMPILE=0`` removes even a current build."""
    build_env.setenv("COOLMUSCLE_COMPILE", "0")
    assert not compiler.will_compile()
    outcome = compiler.build(accel, fake_build)
    assert outcome == compiler.Outcome(False, "COOLMUSCLE_COMPILE=0")
    assert sorted(p.name for p in fake_build.iterdir()) == ["manifest.json"]
    assert accel.read_manifest(fake_build) == (
        None, "not compiled at install time: COOLMUSCLE_COMPILE=0")


def test_a_current_build_is_left_as_it_is(fake_build: Path,
                                          build_env: pytest.MonkeyPatch) -> None:
    before = (fake_build / "manifest.json").read_bytes()
    assert compiler.build(accel, fake_build) == compiler.Outcome(True, "current")
    assert (fake_build / "manifest.json").read_bytes() == before


def test_without_a_c_compiler_the_sources_run_and_the_manifest_says_why(
        tmp_path: Path, build_env: pytest.MonkeyPatch) -> None:
    build_env.setenv("CC", "/no/such/cc -pthread")
    assert compiler.missing() == "no C compiler (/no/such/cc not found)"
    assert not compiler.will_compile()
    logged: list[str] = []
    outcome = compiler.build(accel, tmp_path / "out", log=logged.append)
    assert outcome == compiler.Outcome(False, "no C compiler (/no/such/cc not found)")
    assert accel.read_manifest(tmp_path / "out")[1] == (
        "not compiled at install time: no C compiler (/no/such/cc not found)")
    assert logged == ["the hot modules are not compiled (no C compiler (/no/such/cc not "
                      "found)); the sources run"]


def test_without_the_python_headers_the_sources_run(
        tmp_path: Path, build_env: pytest.MonkeyPatch) -> None:
    build_env.setattr(compiler.sysconfig, "get_paths", lambda: {"include": str(tmp_path)})
    why = compiler.missing()
    assert why is not None and why.startswith(f"no Python headers ({tmp_path}/Python.h")


def test_compile_1_fails_a_build_that_cannot_compile_and_writes_nothing(
        tmp_path: Path, build_env: pytest.MonkeyPatch) -> None:
    build_env.setenv("COOLMUSCLE_COMPILE", "1")
    build_env.setenv("CC", "/no/such/cc")
    with pytest.raises(compiler.CompileError, match=r"no C compiler \(/no/such/cc"):
        compiler.build(accel, tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_a_failed_compile_keeps_the_sources_with_its_last_line(
        tmp_path: Path, build_env: pytest.MonkeyPatch) -> None:
    """mypyc or gcc failing (here a setup script that fails at once): the end of its
    output is logged, its last line is the reason, the sources run."""
    build_env.setattr(compiler, "_SETUP", "import sys\nprint('warming up')\n"
                      "sys.exit('error: command gcc failed with exit code 1')\n")
    logged: list[str] = []
    outcome = compiler.build(accel, tmp_path / "out", log=logged.append)
    why = "mypyc or the C compiler failed: error: command gcc failed with exit code 1"
    assert outcome == compiler.Outcome(False, why)
    assert logged[0] == "warming up\nerror: command gcc failed with exit code 1"
    assert accel.read_manifest(tmp_path / "out")[1] == f"not compiled at install time: {why}"


def test_a_bad_compile_setting_is_one_line(build_env: pytest.MonkeyPatch,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    build_env.setenv("COOLMUSCLE_COMPILE", "yes")
    assert not compiler.will_compile()
    assert accel_tool.main(["build", "--force"]) == 1
    assert capsys.readouterr().err == ("compiling the hot modules failed: "
                                       "COOLMUSCLE_COMPILE must be 0, 1 or auto, not 'yes'\n")


def test_a_build_that_does_not_load_leaves_the_sources_running(fake_build: Path) -> None:
    """A current manifest whose shared library cannot be loaded (here an empty file):
    :func:`coolmuscle._accel.install` takes its finder back and says why."""
    code = ("import os, sys; from pathlib import Path; import coolmuscle._accel as a; "
            "del os.environ['COOLMUSCLE_PURE']; a.BUILD_DIR = Path(sys.argv[1]); "
            "a.install(); import coolmuscle.sim.kernel as k; print(a.describe()); "
            "print(k.__file__)")
    env = dict(os.environ, COOLMUSCLE_PURE="1")
    described, kernel = subprocess.run(
        [sys.executable, "-c", code, str(fake_build)], env=env, capture_output=True,
        text=True, check=True).stdout.splitlines()
    assert described.startswith("hot modules: sources (the compiled modules do not load: ")
    assert kernel.endswith("kernel.py")

"""The compiled hot modules (coolmuscle/_accel.py, docs/performance.md "Compiled hot
modules"): beside their sources, in use when the build stamp says they are current,
never when stale (an edit, a build cut short, ``COOLMUSCLE_PURE``), and giving the same
bytes as the sources; the build (coolmuscle/tools/accel/compiler.py) compiles, keeps the
sources or fails as ``COOLMUSCLE_COMPILE`` and the machine say.  tests/test_packaging.py
builds and installs real wheels.

The compiled code must not change the motion (traces identical, and the same as the
exact model): tests/accel_worker.py runs every example and
golden transcript with a 1 ms trace, a 4-axis csp stream and a 15-motor PTP bank, once
compiled and once with ``COOLMUSCLE_PURE=1``; the two digests must be equal line by line.
"""

from __future__ import annotations

import json
import os
import shutil
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


def test_a_fresh_process_imports_the_compiled_modules_beside_their_sources(
        built: None) -> None:
    code = ("import coolmuscle._accel as a, coolmuscle.motor.motion.dynamics as d, "
            "coolmuscle.sim.kernel as k; print(a.active(), d.__file__, k.__file__)")
    env = {k: v for k, v in os.environ.items() if k != "COOLMUSCLE_PURE"}
    active, *files = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                                    text=True, check=True).stdout.split()
    assert active == "True"
    for found, source in zip(files, ("motor/motion/dynamics", "sim/kernel"), strict=True):
        assert found.startswith(f"{accel.PACKAGE_DIR}/{source}.cpython-") and \
            found.endswith(".so"), found


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


# -- the stamp: what is refused, and a copy of the package edited for real --------------
@pytest.fixture
def stamp(built: None) -> dict[str, object]:
    values = accel.read_stamp(accel.PACKAGE_DIR)
    assert values is not None
    return values


def test_a_current_build_is_accepted(stamp: dict[str, object]) -> None:
    assert accel.refusal(stamp) is None
    assert stamp["SOURCES"] == accel.source_stats()      # the sources' sizes and times


def test_an_edited_source_turns_the_whole_build_off(stamp: dict[str, object]) -> None:
    sources = dict(stamp["SOURCES"])                      # type: ignore[call-overload]
    size, mtime = sources["motor/motion/planner.py"]
    sources["motor/motion/planner.py"] = [size + 1, mtime]
    assert accel.refusal(dict(stamp, SOURCES=sources)) == (
        "a hot module changed since it was compiled (motor/motion/planner.py); "
        "python -m coolmuscle.tools.accel build, or pip install again")


@pytest.mark.parametrize("change, words", [
    ({"CACHE_TAG": "cpython-399"}, "compiled for cpython-399"),
    ({"MODULES": ["coolmuscle.motor.motion.expoly"]}, "another module list"),
    ({"FILES": None}, "malformed"),
    ({"FILES": ["sim/gone.cpython-311-x86_64-linux-gnu.so"]}, "a compiled file is missing"),
    ({"COMPILED": False, "REASON": "not compiled at install time: no C compiler"},
     "not compiled at install time: no C compiler"),
])
def test_a_build_for_something_else_is_refused(stamp: dict[str, object],
                                               change: dict[str, object], words: str) -> None:
    why = accel.refusal(dict(stamp, **change))
    assert why is not None and words in why


def test_a_missing_or_damaged_stamp_is_no_build(tmp_path: Path) -> None:
    assert accel.read_stamp(str(tmp_path)) is None
    assert accel.refusal(None) == (
        "not compiled; python -m coolmuscle.tools.accel build, or pip install again")
    (tmp_path / accel.STAMP_FILE).write_text("COMPILED = (\n", encoding="utf-8")
    with pytest.raises(ValueError, match="build stamp unreadable"):
        accel.read_stamp(str(tmp_path))


WHICH = ("import coolmuscle, coolmuscle.sim.kernel as k, coolmuscle.motor.motion.dynamics as d;"
         " from coolmuscle import _accel as a; print(a.describe()); print(k.__file__);"
         " print(d.__file__)")


def which(package: Path, **env: str) -> tuple[str, list[str]]:
    """In a fresh interpreter on the copy: ``--version``'s line, and the files of two hot
    modules relative to the copy."""
    environ = {k: v for k, v in os.environ.items() if k != "COOLMUSCLE_PURE"}
    environ.update(PYTHONPATH=str(package.parent), **env)
    line, *files = subprocess.run([sys.executable, "-c", WHICH], env=environ,
                                  capture_output=True, text=True, check=True,
                                  timeout=60).stdout.splitlines()
    return line, [str(Path(f).relative_to(package)) for f in files]


@pytest.fixture
def package_copy(built: None, tmp_path: Path) -> Path:
    """A copy of the package with its compiled modules and stamp (times kept)."""
    copy = tmp_path / "src" / "coolmuscle"
    shutil.copytree(accel.PACKAGE_DIR, copy,
                    ignore=shutil.ignore_patterns("__pycache__", ".accel-build.lock"))
    return copy


def test_an_edit_a_touch_a_rebuild_and_pure_in_a_copy_of_the_package(package_copy: Path) -> None:
    """The guarantee end to end, in a fresh interpreter each time: compiled when current;
    one hot source edited (one byte) turns every compiled module off and says which;
    the same file only touched too, until the build tool records its time again
    (comparing the bytes, without compiling); ``COOLMUSCLE_PURE=1`` runs the sources."""
    so = ".cpython-311-x86_64-linux-gnu.so"
    compiled = [f"sim/kernel{so}", f"motor/motion/dynamics{so}"]
    sources = ["sim/kernel.py", "motor/motion/dynamics.py"]
    line, files = which(package_copy)
    assert line.startswith("hot modules: compiled (") and files == compiled

    planner = package_copy / "motor" / "motion" / "planner.py"
    original = planner.read_bytes()
    planner.write_bytes(original + b"\n")
    line, files = which(package_copy)
    assert line == ("hot modules: sources (a hot module changed since it was compiled "
                    "(motor/motion/planner.py); python -m coolmuscle.tools.accel build, "
                    "or pip install again)")
    assert files == sources

    planner.write_bytes(original)                   # the same bytes, a new time
    assert which(package_copy)[1] == sources
    environ = {k: v for k, v in os.environ.items() if k != "COOLMUSCLE_PURE"}
    environ["PYTHONPATH"] = str(package_copy.parent)
    done = subprocess.run([sys.executable, "-m", "coolmuscle.tools.accel", "build"],
                          env=environ, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stdout.startswith("current (sources touched"), done
    assert which(package_copy)[1] == compiled
    line, files = which(package_copy, COOLMUSCLE_PURE="1")
    assert line == "hot modules: sources (COOLMUSCLE_PURE is set)" and files == sources


def test_a_build_cut_short_runs_the_sources(package_copy: Path) -> None:
    """While the compiled files are replaced the stamp says so and names them: a build
    stopped there (here: the stamp of that moment, the old files still present) runs
    the sources, though the extension modules are beside them."""
    values = accel.read_stamp(str(package_copy))
    assert values is not None
    compiler._write_stamp(accel, package_copy, {
        "COMPILED": False, "FILES": values["FILES"],
        "REASON": "a build of the compiled modules was cut short; python -m "
                  "coolmuscle.tools.accel build, or pip install again"})
    line, files = which(package_copy)
    assert line.startswith("hot modules: sources (a build of the compiled modules was cut short")
    assert files == ["sim/kernel.py", "motor/motion/dynamics.py"]


def test_clean_removes_every_compiled_file_and_the_stamp(package_copy: Path,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(accel, "PACKAGE_DIR", str(package_copy))
    assert accel_tool.main(["clean"]) == 0
    assert not list(package_copy.rglob("*.so"))
    assert not (package_copy / accel.STAMP_FILE).exists()
    line, files = which(package_copy)
    assert line == ("hot modules: sources (not compiled; python -m coolmuscle.tools.accel "
                    "build, or pip install again)")
    assert files == ["sim/kernel.py", "motor/motion/dynamics.py"]


def test_the_build_tool_answers_status_and_bad_usage(
        built: None, capsys: pytest.CaptureFixture[str]) -> None:
    assert accel_tool.main(["status"]) == 0
    assert "built in place from the current sources by mypyc" in capsys.readouterr().out
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
        stamp: dict[str, object], monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(compiler, "find_spec", lambda name: None)
    assert accel_tool.main(["build", "--force"]) == 1
    assert "no mypy (mypyc)" in capsys.readouterr().err
    assert accel.read_stamp(accel.PACKAGE_DIR) == stamp        # nothing removed
    assert accel.refusal(stamp) is None


def test_a_read_only_install_gets_one_line_not_a_traceback(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """The package folder cannot be written (here a path through a file: as root a mode
    bit would not stop the build)."""
    (tmp_path / "afile").write_text("")
    monkeypatch.setattr(accel, "PACKAGE_DIR", str(tmp_path / "afile" / "coolmuscle"))
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


def test_compile_0_keeps_the_sources_and_says_so(package_copy: Path,
                                                 build_env: pytest.MonkeyPatch) -> None:
    """The escape hatch: ``COOLMUSCLE_COMPILE=0`` removes even a current build."""
    build_env.setenv("COOLMUSCLE_COMPILE", "0")
    assert not compiler.will_compile()
    outcome = compiler.build(accel, package_copy, in_place=False)
    assert outcome == compiler.Outcome(False, "COOLMUSCLE_COMPILE=0")
    assert not list(package_copy.rglob("*.so"))
    assert accel.refusal(accel.read_stamp(str(package_copy)), str(package_copy)) == (
        "not compiled at install time: COOLMUSCLE_COMPILE=0")


def test_a_current_build_is_left_as_it_is(stamp: dict[str, object],
                                          build_env: pytest.MonkeyPatch) -> None:
    path = Path(accel.PACKAGE_DIR, accel.STAMP_FILE)
    before = path.read_bytes()
    assert compiler.build(accel, Path(accel.PACKAGE_DIR), in_place=True) == \
        compiler.Outcome(True, "current")
    assert path.read_bytes() == before


def test_without_a_c_compiler_the_sources_run_and_the_stamp_says_why(
        tmp_path: Path, build_env: pytest.MonkeyPatch) -> None:
    build_env.setenv("CC", "/no/such/cc -pthread")
    assert compiler.missing() == "no C compiler (/no/such/cc not found)"
    assert not compiler.will_compile()
    logged: list[str] = []
    out = tmp_path / "out"
    outcome = compiler.build(accel, out, in_place=False, log=logged.append)
    assert outcome == compiler.Outcome(False, "no C compiler (/no/such/cc not found)")
    assert accel.refusal(accel.read_stamp(str(out)), str(out)) == (
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
        compiler.build(accel, tmp_path / "out", in_place=False)
    assert not (tmp_path / "out").exists()


def test_a_failed_compile_keeps_the_sources_with_its_last_line(
        tmp_path: Path, build_env: pytest.MonkeyPatch) -> None:
    """mypyc or gcc failing (here a setup script that fails at once): the end of its
    output is logged, its last line is the reason, the sources run."""
    build_env.setattr(compiler, "_SETUP", "import sys\nprint('warming up')\n"
                      "sys.exit('error: command gcc failed with exit code 1')\n")
    logged: list[str] = []
    out = tmp_path / "out"
    outcome = compiler.build(accel, out, in_place=False, log=logged.append)
    why = "mypyc or the C compiler failed: error: command gcc failed with exit code 1"
    assert outcome == compiler.Outcome(False, why)
    assert logged[0].startswith("C compiler flags for the whole library: ")
    assert logged[1] == "warming up\nerror: command gcc failed with exit code 1"
    assert accel.refusal(accel.read_stamp(str(out)), str(out)) == \
        f"not compiled at install time: {why}"


def refusing_cc(where: Path, refused: str) -> str:
    """A C compiler (gcc behind a shell script) that fails when given a flag matching
    the shell pattern ``refused``."""
    script = where / "refusing-cc"
    script.write_text(f'#!/bin/sh\nfor a in "$@"; do case "$a" in {refused}) exit 1;; esac; done\n'
                      'exec gcc "$@"\n')
    script.chmod(0o755)
    return str(script)


@pytest.mark.skipif(sys.platform == "win32", reason="GCC's and Clang's flags (MSVC: none)")
def test_link_time_flags_are_the_first_set_the_c_compiler_takes(
        tmp_path: Path, build_env: pytest.MonkeyPatch) -> None:
    """The library is optimised as a whole with its symbols hidden where the compiler
    takes it (GCC: ``-flto=auto``); a compiler that refuses link-time optimisation
    still gets hidden symbols, one that refuses those too gets none, a missing one none:
    the build then goes on (or says why) as before."""
    build_env.setenv("CC", "gcc -pthread")
    assert compiler.link_time_flags(tmp_path) == ("-fvisibility=hidden", "-flto=auto")
    build_env.setenv("CC", refusing_cc(tmp_path, "-flto=*"))
    assert compiler.link_time_flags(tmp_path) == ("-fvisibility=hidden",)
    build_env.setenv("CC", refusing_cc(tmp_path, "-fvisibility=*"))
    assert compiler.link_time_flags(tmp_path) == ()
    build_env.setenv("CC", "/no/such/cc")
    assert compiler.link_time_flags(tmp_path) == ()


def test_a_bad_compile_setting_is_one_line(build_env: pytest.MonkeyPatch,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    build_env.setenv("COOLMUSCLE_COMPILE", "yes")
    assert not compiler.will_compile()
    assert accel_tool.main(["build", "--force"]) == 1
    assert capsys.readouterr().err == ("compiling the hot modules failed: "
                                       "COOLMUSCLE_COMPILE must be 0, 1 or auto, not 'yes'\n")


def test_no_hot_module_declares_a_final_tuple_of_floats() -> None:
    """mypyc 1.19 checks a ``Final`` tuple of floats for "unset" with the test inverted
    where a function reads it in some expressions: the read raises ``NameError`` (or,
    caught, changes the answer).  The hot modules keep such tuples plain."""
    import ast
    offenders = []
    for module in accel.MODULES:
        path = Path(accel.PACKAGE_DIR) / accel.source_relpath(module)
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            if isinstance(node, ast.AnnAssign) and "Final" in ast.unparse(node.annotation) \
                    and isinstance(node.value, ast.Tuple) \
                    and any(isinstance(e, ast.Constant) and isinstance(e.value, float)
                            for e in ast.walk(node.value)):
                offenders.append(f"{module}: {ast.unparse(node.target)}")
    assert offenders == []


def test_the_safety_nets_rest_piece_of_a_free_motor_makes_no_torque() -> None:
    """dynamics._rest_piece (MAX_PIECES reached) of a servo that is off reads the zero
    function; compiled, this raised NameError while expoly.ZERO was a Final tuple."""
    from dataclasses import replace

    from coolmuscle.motor.motion import dynamics
    from coolmuscle.motor.motion.plant import Plant
    drive = Plant().drive(1000, limit_percent_of_rated=100.0, enabled=True)
    piece = dynamics._rest_piece(0.5, 12.0, (3.0, 0.0, 0.0, 0.0, 0.0),
                                 replace(drive, enabled=False))
    assert piece.torque == (0.0, 0.0, 0.0, 0.0, 0.0)
    assert piece.pos[0] == 12.0 and piece.start == 0.5

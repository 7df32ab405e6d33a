"""The package build compiles the hot modules (docs/performance.md "Compiled hot
modules"): what a user gets from ``python -m build`` / ``pip install .``.

A copy of the checkout is built as ``python -m build`` builds it (an sdist, then a wheel
from the sdist, each in its own isolated build environment with the pinned build
requirements).  Each wheel is installed into a fresh virtual environment (``--no-deps``:
the dependencies come from this environment's site-packages through a ``.pth`` file,
which adds the path but not the editable install's own ``.pth``).  There:

* with a C compiler, ``coolmuscle --version`` says compiled, every hot module is a
  ``.so`` from the wheel, and a reference run (a guide example, three golden
  transcripts with 1 ms traces, a csp stream, a 15-motor bank: tests/accel_worker.py
  ``--sample``) gives the same bytes compiled, with ``COOLMUSCLE_PURE=1``, and as this
  checkout's sources;
* without one (``CC`` names no program), the build still succeeds with a pure wheel,
  ``coolmuscle --version`` says why the sources run, and the run gives the same bytes.

Slow (the compile is 30-120 s on a busy 2-CPU machine); both tests share one worker.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

import coolmuscle
import coolmuscle._accel as accel

ROOT = Path(__file__).resolve().parents[1]
WORKER = Path(__file__).with_name("accel_worker.py")

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("packaging"),
              pytest.mark.timeout(900)]

#: Variables of this environment that would change what the build or the runs do.
_OURS = ("COOLMUSCLE_PURE", "COOLMUSCLE_COMPILE", "CC", "PYTHONPATH")


def clean_env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in _OURS}
    env.update(extra)
    return env


def run(cmd: list[str], env: dict[str, str], timeout: float = 600,
        cwd: Path | None = None) -> str:
    done = subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True,
                          timeout=timeout)
    assert done.returncode == 0, (cmd, "\n".join((done.stdout + done.stderr).splitlines()[-30:]))
    return done.stdout


def copy_checkout(tree: Path) -> None:
    """The files a build reads, without this tree's compiled modules or caches."""
    shutil.copytree(ROOT / "src", tree / "src", ignore=shutil.ignore_patterns(
        "_compiled", "__pycache__", "*.egg-info", ".mypy_cache", ".accel-build.lock"))
    for name in ("pyproject.toml", "setup.py", "README.md", "LICENSE"):
        shutil.copy2(ROOT / name, tree / name)


@pytest.fixture(scope="module")
def sdist(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``python -m build --sdist`` of a copy of the checkout (no build directory, no
    compiled modules or caches of this tree come along)."""
    tree = tmp_path_factory.mktemp("tree")
    copy_checkout(tree)
    out = tmp_path_factory.mktemp("sdist")
    run([sys.executable, "-m", "build", "--sdist", "--outdir", str(out), str(tree)],
        clean_env())
    (found,) = out.glob("coolmuscle-*.tar.gz")
    return found


def build_wheel(sdist: Path, out: Path, env: dict[str, str]) -> Path:
    """A wheel built from the sdist, as ``python -m build`` does after the sdist."""
    run([sys.executable, "-m", "build", "--wheel", "--outdir", str(out), str(sdist)], env)
    (wheel,) = out.glob("coolmuscle-*.whl")
    return wheel


def link_deps(python: Path) -> None:
    """This environment's site-packages on ``python``'s path (the dependencies)."""
    site = Path(run([str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                    clean_env()).strip())
    deps = {sysconfig.get_path("purelib"), sysconfig.get_path("platlib")}
    (site / "coolmuscle-test-deps.pth").write_text("\n".join(sorted(deps)) + "\n")


def fresh_venv(where: Path, wheel: Path) -> Path:
    """A new virtual environment with ``wheel`` installed; its python."""
    run([sys.executable, "-m", "venv", "--without-pip", str(where)], clean_env())
    python = where / "bin" / "python"
    run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps",
         "--no-index", "--no-cache-dir", "--quiet", str(wheel)], clean_env())
    link_deps(python)
    return python


def sample(python: Path, **extra: str) -> tuple[dict[str, object], list[str]]:
    """The reference run's header and digest lines (tests/accel_worker.py --sample)."""
    out = run([str(python), str(WORKER), str(ROOT), "--sample"], clean_env(**extra),
              timeout=300)
    head, *lines = out.splitlines()
    return json.loads(head), lines


@pytest.fixture(scope="module")
def reference() -> list[str]:
    """The reference run on this checkout's sources."""
    head, lines = sample(Path(sys.executable), COOLMUSCLE_PURE="1")
    assert head["compiled"] is False and len(lines) == 7
    return lines


def version_lines(python: Path) -> list[str]:
    return run([str(python.parent / "coolmuscle"), "--version"], clean_env()).splitlines()


def module_files(python: Path) -> dict[str, str]:
    code = ("import importlib, json, coolmuscle._accel as a; "
            "print(json.dumps({m: importlib.import_module(m).__file__ for m in a.MODULES}))")
    return dict(json.loads(run([str(python), "-c", code], clean_env())))


def test_a_wheel_built_with_a_compiler_installs_and_runs_the_compiled_modules(
        sdist: Path, reference: list[str], tmp_path: Path) -> None:
    wheel = build_wheel(sdist, tmp_path / "dist", clean_env(COOLMUSCLE_COMPILE="1"))
    assert not wheel.name.endswith("-py3-none-any.whl"), wheel.name   # a platform wheel
    python = fresh_venv(tmp_path / "venv", wheel)

    assert version_lines(python) == [
        f"coolmuscle {coolmuscle.__version__}",
        f"hot modules: compiled ({len(accel.MODULES)} modules built from the current "
        "sources by mypyc 1.19.0)"]
    files = module_files(python)
    venv_lib = tmp_path / "venv" / "lib"
    assert set(files) == set(accel.MODULES)
    for name, path in files.items():
        assert path.endswith(".so") and "/site-packages/coolmuscle/_compiled/" in path \
            and Path(path).is_relative_to(venv_lib), (name, path)

    head, lines = sample(python)
    assert head == {"compiled": True,
                    "reason": "built from the current sources by mypyc 1.19.0"}
    assert lines == reference
    head, lines = sample(python, COOLMUSCLE_PURE="1")
    assert head == {"compiled": False, "reason": "COOLMUSCLE_PURE is set"}
    assert lines == reference


def test_without_a_c_compiler_the_build_succeeds_and_the_sources_run(
        sdist: Path, reference: list[str], tmp_path: Path) -> None:
    wheel = build_wheel(sdist, tmp_path / "dist", clean_env(CC="/no/such/cc"))
    assert wheel.name.endswith("-py3-none-any.whl"), wheel.name       # a pure wheel
    python = fresh_venv(tmp_path / "venv", wheel)

    why = "not compiled at install time: no C compiler (/no/such/cc not found)"
    assert version_lines(python) == [f"coolmuscle {coolmuscle.__version__}",
                                     f"hot modules: sources ({why})"]
    assert all(path.endswith(".py") for path in module_files(python).values())
    head, lines = sample(python)
    assert head == {"compiled": False, "reason": why}
    assert lines == reference


def test_a_stale_compiled_module_in_the_tree_does_not_break_an_editable_install(
        tmp_path: Path) -> None:
    """``pip install -e .`` in a checkout whose ``src/coolmuscle/_compiled/`` keeps a
    module an earlier build compiled and this one does not (a stale ``chain/daisy``
    ``.so``): the compiled tree is build_accel's output, not a source package.  Before,
    setuptools listed the stale folder as a package and build_accel then removed it:
    "package directory ... does not exist", the install failed."""
    tree = tmp_path / "tree"
    copy_checkout(tree)
    stale = tree / "src" / "coolmuscle" / "_compiled" / "coolmuscle" / "chain"
    stale.mkdir(parents=True)
    (stale / "daisy.cpython-311-x86_64-linux-gnu.so").write_bytes(b"\x7fELF stale")
    run([sys.executable, "-m", "venv", "--without-pip", str(tmp_path / "venv")], clean_env())
    python = tmp_path / "venv" / "bin" / "python"
    run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps",
         "--quiet", "-e", str(tree)], clean_env(COOLMUSCLE_COMPILE="0"))
    link_deps(python)
    assert version_lines(python)[1].startswith("hot modules: sources (")
    where = run([str(python), "-c", "import coolmuscle.chain.daisy as d; print(d.__file__)"],
                clean_env()).strip()
    assert where == str(tree / "src" / "coolmuscle" / "chain" / "daisy.py")

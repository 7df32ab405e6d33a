"""The package build compiles the hot modules (docs/performance.md "Compiled hot
modules"): what a user gets from ``python -m build`` / ``pip install .``.

A copy of the checkout is built as ``python -m build`` builds it (an sdist, then a wheel
from the sdist, each in its own isolated build environment with the pinned build
requirements).  Each wheel is installed into a fresh virtual environment (``--no-deps``:
the dependencies come from this environment's site-packages through a ``.pth`` file,
which adds the path but not the editable install's own ``.pth``).  There:

* with a C compiler, ``coolmuscle --version`` says compiled, every hot module is a
  ``.so`` from the wheel beside its source, their shared library exports only its init
  function (optimised as a whole when linked), and a reference run (a guide example, three golden
  transcripts with 1 ms traces, a csp stream, a 15-motor bank: tests/accel_worker.py
  ``--sample``) gives the same bytes compiled, with ``COOLMUSCLE_PURE=1``, and as this
  checkout's sources;
* without one (``CC`` names no program), the build still succeeds with a pure wheel,
  ``coolmuscle --version`` says why the sources run, and the run gives the same bytes;
* asked for one (``COOLMUSCLE_COMPILE=0``), the wheel is pure, and installed with only
  the dependencies its metadata names without an extra (linked from this environment:
  pyserial, typer, rich and theirs; no compiler, no matplotlib, numpy or aiohttp) it
  runs the demo's ``coolmuscle run examples/2.1-operation.cml``, while ``--plot``,
  ``sim --web`` and ``compare`` each say in one line which extra they need; its
  ``all`` extra asks for every extra, and this environment (constraints.txt, what the
  scripts install) meets every range it names.

Slow (the compile is 30-120 s on a busy 2-CPU machine); both tests share one worker.
"""

from __future__ import annotations

import ctypes
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
        "_compiled", "*.so", "_build_stamp.py", "__pycache__", "*.egg-info", ".mypy_cache",
        ".accel-build.lock"))
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

    metadata = run([str(python), "-c", "import importlib.metadata as m; "
                    "print(m.version('coolmuscle'))"], clean_env()).strip()
    assert metadata == coolmuscle.__version__          # pyproject reads it from the package
    assert version_lines(python) == [
        f"coolmuscle {coolmuscle.__version__}",
        f"hot modules: compiled ({len(accel.MODULES)} modules built with the package by "
        "mypyc 1.19.0)"]
    files = module_files(python)
    site = tmp_path / "venv" / "lib" / f"python{sys.version_info[0]}.{sys.version_info[1]}" \
        / "site-packages" / "coolmuscle"
    assert set(files) == set(accel.MODULES)
    for name, path in files.items():          # mypyc's layout: beside the source
        source = site / accel.source_relpath(name)
        assert path.startswith(str(source)[:-3] + ".cpython-") and path.endswith(".so") \
            and source.is_file(), (name, path)
    # optimised as a whole when linked (compiler.LINK_TIME): the library exports its
    # init function only, every compiled function is hidden inside it
    library = ctypes.CDLL(str(next(site.glob("_hot__mypyc.*.so"))))
    assert hasattr(library, "PyInit__hot__mypyc")
    assert not hasattr(library, "CPyDef_sim___kernel___Kernel___run")
    assert not hasattr(library, "CPyDef_motor___motion___dynamics____placed")

    head, lines = sample(python)
    assert head == {"compiled": True, "reason": "built with the package by mypyc 1.19.0"}
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


def requirement_closure(names: list[str]) -> set[str]:
    """The distributions of this environment that ``names`` need (markers evaluated,
    no extras): what ``pip install`` of a wheel requiring them brings."""
    from importlib.metadata import distribution

    from packaging.requirements import Requirement
    from packaging.utils import canonicalize_name

    found: set[str] = set()
    todo = [Requirement(n) for n in names]
    while todo:
        req = todo.pop()
        if req.marker is not None and not req.marker.evaluate({"extra": ""}):
            continue
        name = canonicalize_name(req.name)
        if name in found:
            continue
        found.add(name)
        todo += [Requirement(r) for r in distribution(req.name).requires or []]
    return found


def link_only(python: Path, dists: set[str], where: Path) -> None:
    """Only the distributions ``dists`` of this environment on ``python``'s path: their
    top-level modules and metadata linked into ``where``."""
    from importlib.metadata import distribution

    where.mkdir()
    for name in dists:
        dist = distribution(name)
        base = Path(str(dist.locate_file("")))
        for top in {Path(str(f)).parts[0] for f in dist.files or []}:
            if not (where / top).exists() and (base / top).exists() and ".." not in top:
                (where / top).symlink_to(base / top)
    site = Path(run([str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                    clean_env()).strip())
    (site / "coolmuscle-test-core.pth").write_text(f"{where}\n")


def wheel_requirements(python: Path) -> list[str]:
    code = "import importlib.metadata as m; print('\\n'.join(m.requires('coolmuscle')))"
    return run([str(python), "-c", code], clean_env()).splitlines()


def test_a_pure_wheel_installs_the_light_core_and_names_each_missing_extra(
        sdist: Path, tmp_path: Path) -> None:
    from packaging.requirements import Requirement

    wheel = build_wheel(sdist, tmp_path / "dist", clean_env(COOLMUSCLE_COMPILE="0"))
    assert wheel.name.endswith("-py3-none-any.whl"), wheel.name       # asked for: pure
    run([sys.executable, "-m", "venv", "--without-pip", str(tmp_path / "venv")], clean_env())
    python = tmp_path / "venv" / "bin" / "python"
    run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps",
         "--no-index", "--no-cache-dir", "--quiet", str(wheel)], clean_env())
    requires = [Requirement(r) for r in wheel_requirements(python)]
    core = [str(r) for r in requires if r.marker is None]
    assert sorted(Requirement(r).name for r in core) == [
        "mypy_extensions", "pyserial", "rich", "typer"]
    dists = requirement_closure(core)       # typer brings pydantic and theirs: 14 today
    assert len(dists) <= 16, sorted(dists)
    assert not dists & {"numpy", "matplotlib", "aiohttp", "prompt-toolkit", "scipy",
                        "pymodbus", "dask", "distributed"}, sorted(dists)
    link_only(python, dists, tmp_path / "core")
    absent = run([str(python), "-c", "import importlib.util as u; print([m for m in "
                  "('matplotlib', 'numpy', 'aiohttp', 'prompt_toolkit', 'scipy', 'pymodbus') "
                  "if u.find_spec(m) is None])"], clean_env()).strip()
    assert absent == "['matplotlib', 'numpy', 'aiohttp', 'prompt_toolkit', 'scipy', 'pymodbus']"

    command = str(python.parent / "coolmuscle")
    assert version_lines(python)[1] == \
        "hot modules: sources (not compiled at install time: COOLMUSCLE_COMPILE=0)"
    demo = ROOT / "examples" / "2.1-operation.cml"
    out = run([command, "run", str(demo), "--trace", str(tmp_path / "demo.csv")], clean_env())
    assert out.splitlines()[-1].endswith("< Px.1=0") and (tmp_path / "demo.csv").is_file()
    for args, extra, what, module in (
            (["run", str(demo), "--plot", str(tmp_path / "demo.png")], "plot",
             "plotting (--plot)", "matplotlib"),
            (["sim", "--no-state", "--web", "0"], "web", "the web page", "aiohttp"),
            (["compare", str(ROOT / "examples" / "twin" / "session.cml")], "twin",
             "the twin's plots (compare, fit)", "matplotlib")):
        done = subprocess.run([command, *args], env=clean_env(), capture_output=True,
                              text=True, timeout=120, stdin=subprocess.DEVNULL)
        assert (done.returncode, done.stderr) == (2, (
            f"coolmuscle: error: {what} needs the '{extra}' extra ({module} is not "
            f'installed): pip install "coolmuscle[{extra}]"\n')), (args, done)
    assert not (tmp_path / "demo.png").exists()

    extras = {str(m).split('"')[1] for r in requires if (m := r.marker) is not None}
    assert extras == {"plot", "web", "term", "twin", "dask", "peers", "all", "test", "docs",
                      "accel"}
    everything = [r for r in requires if r.marker is not None
                  and r.marker.evaluate({"extra": "all"})]
    assert [(r.name, sorted(r.extras)) for r in everything] == [
        ("coolmuscle", ["dask", "peers", "plot", "term", "twin", "web"])]
    from importlib.metadata import version
    for r in requires:            # what the scripts install meets every range of [all]
        extra = str(r.marker).split('"')[1] if r.marker is not None else ""
        if extra in ("", "plot", "web", "term", "twin", "dask", "peers") \
                and r.name != "coolmuscle":
            assert r.specifier.contains(version(r.name)), (str(r), version(r.name))


def test_stale_compiled_files_in_the_tree_do_not_break_or_enter_an_editable_install(
        tmp_path: Path) -> None:
    """``pip install -e .`` (here without compiling) in a checkout holding compiled files
    an earlier build left: an extension module beside a source that is no longer
    compiled (``chain/daisy``, a damaged one) and the folder of the layout before the
    build stamp (``_compiled/``, which setuptools would list as a package).  The build
    removes both: the sources run and ``--version`` says why."""
    tree = tmp_path / "tree"
    copy_checkout(tree)
    package = tree / "src" / "coolmuscle"
    (package / "chain" / "daisy.cpython-311-x86_64-linux-gnu.so").write_bytes(b"\x7fELF stale")
    old = package / "_compiled" / "coolmuscle" / "chain"
    old.mkdir(parents=True)
    (old / "daisy.cpython-311-x86_64-linux-gnu.so").write_bytes(b"\x7fELF stale")
    run([sys.executable, "-m", "venv", "--without-pip", str(tmp_path / "venv")], clean_env())
    python = tmp_path / "venv" / "bin" / "python"
    run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps",
         "--quiet", "-e", str(tree)], clean_env(COOLMUSCLE_COMPILE="0"))
    link_deps(python)
    assert version_lines(python)[1] == \
        "hot modules: sources (not compiled at install time: COOLMUSCLE_COMPILE=0)"
    where = run([str(python), "-c", "import coolmuscle.chain.daisy as d; print(d.__file__)"],
                clean_env()).strip()
    assert where == str(package / "chain" / "daisy.py")
    assert not list(package.rglob("*.so")) and not (package / "_compiled").exists()

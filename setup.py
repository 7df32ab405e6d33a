"""The package build's one step beyond pyproject.toml: the hot modules compiled with
mypyc (docs/performance.md "Compiled hot modules").

``pip install .``, ``pip install -e .`` and ``python -m build`` run the ``build_accel``
step after the usual ones.  It compiles :data:`coolmuscle._accel.MODULES` when mypyc, a
C compiler and the Python headers are there, in mypyc's layout (each module's
extension beside its source): into the wheel, or in place in the source tree for an
editable install (where ``coolmuscle._accel`` then runs the sources as soon as one of
them is edited).  It writes the build stamp ``coolmuscle/_build_stamp.py`` last, which
says at import which copy runs.  Without a compiler the build still succeeds and the
sources run; ``COOLMUSCLE_COMPILE=0`` skips compiling and ``COOLMUSCLE_COMPILE=1``
makes it required (coolmuscle/tools/accel/compiler.py).
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

from setuptools import Command, setup
from setuptools.command.build import build
from setuptools.dist import Distribution

PACKAGE = Path(__file__).resolve().parent / "src" / "coolmuscle"


def _load(name: str, path: Path) -> ModuleType:
    """A standard-library-only module of the package, loaded by path: the build
    environment has none of coolmuscle's dependencies, so the package itself is not
    imported."""
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None, path
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


accel = _load("_coolmuscle_build_accel", PACKAGE / "_accel.py")
compiler = _load("_coolmuscle_build_compiler", PACKAGE / "tools" / "accel" / "compiler.py")


#: What starts each line the compile says (pip shows them with ``-v``; scripts/_env.sh
#: shows these lines and keeps the rest in its log).
SAY = "coolmuscle build: "


def say(text: str) -> None:
    for line in text.splitlines():
        print(SAY + line, file=sys.stderr, flush=True)


class BuildAccel(Command):
    """Compile the hot modules with mypyc, or record why the sources run."""

    description = "compile the hot modules with mypyc (the sources run when that cannot be done)"
    user_options: list[tuple[str, str | None, str]] = []

    def initialize_options(self) -> None:
        self.build_lib: str | None = None
        self.editable_mode = False

    def finalize_options(self) -> None:
        self.set_undefined_options("build", ("build_lib", "build_lib"))

    def _dest(self) -> Path:
        if self.editable_mode:            # in place: the editable install imports src/
            return Path(accel.PACKAGE_DIR)
        assert self.build_lib is not None
        return Path(self.build_lib, "coolmuscle")

    def run(self) -> None:
        dest = self._dest()
        lock = dest / ".accel-build.lock" if self.editable_mode else None
        outcome = compiler.build(accel, dest, in_place=self.editable_mode, lock=lock,
                                 log=say)
        say(f"{'compiled' if outcome.compiled else 'sources'}: {outcome.reason}")

    def get_outputs(self) -> list[str]:
        """The compiled files and the stamp this step wrote."""
        dest = self._dest()
        try:
            values = accel.read_stamp(str(dest))
        except ValueError:
            values = None
        if values is None:
            return []
        files = values["FILES"] if isinstance(values["FILES"], list) else []
        return [str(dest / accel.STAMP_FILE)] + [str(dest / str(f)) for f in files]

    def get_output_mapping(self) -> dict[str, str]:
        return {}

    def get_source_files(self) -> list[str]:
        return []


class BuildWithAccel(build):
    sub_commands = build.sub_commands + [("build_accel", None)]


class CoolmuscleDistribution(Distribution):
    """A platform wheel (``cp311-cp311-linux_x86_64``) when the build will compile."""

    def has_ext_modules(self) -> bool:
        return bool(compiler.will_compile())


setup(cmdclass={"build": BuildWithAccel, "build_accel": BuildAccel},
      distclass=CoolmuscleDistribution)

"""A temporary unprivileged user, for the tests of what works without root.

:func:`unprivileged_user` makes a system user (``useradd``), a directory of its own in
/tmp holding a copy of this checkout's ``src/coolmuscle`` (its compiled files left out:
the sources run) and what the test copies in, and finds a Python that user can execute
(this one, or the system's of the same version) with this interpreter's packages on its
path (readable in place).  :meth:`Unprivileged.run` runs a command as the user
(``runuser -u``); at the end its processes are ended by their ids, the user removed
(``userdel``) and the directory deleted, whatever happened.  Where the machine cannot
(not root, no useradd or runuser, no interpreter the user can run) the test is skipped
with the reason.

:func:`veth_lock` is the machine-wide lock every test that makes veth pairs or network
namespaces holds (CONTRIBUTING.md: ``flock /tmp/coolmuscle-veth.lock``).
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import secrets
import shutil
import signal
import site
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LOCK = Path("/tmp/coolmuscle-veth.lock")
#: What the user's Python must import (the command line, pyserial, the peers, pytest).
NEEDED = ("serial", "typer", "rich", "pysoem", "pytest")


@contextlib.contextmanager
def veth_lock() -> Iterator[None]:
    with LOCK.open("a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


@dataclass
class Unprivileged:
    """A user without privileges, its directory (``home``) and its Python."""

    name: str
    home: Path
    python: str = ""
    path: list[str] = field(default_factory=list)

    def env(self, **extra: str) -> dict[str, str]:
        return {"HOME": str(self.home), "PATH": "/usr/bin:/bin:/usr/sbin:/sbin",
                "PYTHONPATH": os.pathsep.join(self.path), "COOLMUSCLE_PURE": "1",
                "LANG": "C.UTF-8", "COLUMNS": "200", "TMPDIR": str(self.home), **extra}

    def run(self, args: Sequence[str], *, cwd: Path | None = None, timeout: float = 300,
            **extra: str) -> subprocess.CompletedProcess[str]:
        """``args`` as this user (environment: :meth:`env`), to its end."""
        env = [f"{key}={value}" for key, value in self.env(**extra).items()]
        return subprocess.run(["runuser", "-u", self.name, "--", "env", "-i", *env, *args],
                              cwd=cwd or self.home, capture_output=True, text=True,
                              timeout=timeout, stdin=subprocess.DEVNULL)

    def coolmuscle(self, *args: str, timeout: float = 300,
                   cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
        return self.run([self.python, "-m", "coolmuscle", *args], timeout=timeout, cwd=cwd)

    def copy(self, source: Path, name: str | None = None) -> Path:
        """``source`` (a file or a folder) copied into the user's directory, its own."""
        target = self.home / (name or source.name)
        if source.is_dir():
            shutil.copytree(source, target, ignore=shutil.ignore_patterns(
                "__pycache__", "*.so", ".pytest_cache"))
        else:
            shutil.copy2(source, target)
        _chown(target, self.name)
        return target

    def processes(self) -> list[int]:
        """The ids of the processes running as this user."""
        uid = _uid(self.name)
        found = []
        for entry in Path("/proc").iterdir():
            with contextlib.suppress(OSError):
                if entry.name.isdigit() and entry.stat().st_uid == uid:
                    found.append(int(entry.name))
        return found


def _uid(name: str) -> int:
    import pwd
    return pwd.getpwnam(name).pw_uid


def _chown(path: Path, user: str) -> None:
    subprocess.run(["chown", "-R", f"{user}:", str(path)], check=True, timeout=60)


def _python_for(user: Unprivileged) -> str | None:
    """An interpreter of this version the user can run, or ``None``."""
    wanted = f"{sys.version_info[0]}.{sys.version_info[1]}"
    for candidate in (sys.executable, shutil.which("python3"), "/usr/bin/python3"):
        if not candidate:
            continue
        done = user.run([candidate, "-c", "import sys; print('%d.%d' % sys.version_info[:2])"],
                        timeout=60)
        if done.returncode == 0 and done.stdout.strip() == wanted:
            return candidate
    return None


@contextlib.contextmanager
def unprivileged_user() -> Iterator[Unprivileged]:
    """A temporary user with a copy of the sources (see the module docstring)."""
    if not hasattr(os, "geteuid") or os.geteuid() != 0:
        pytest.skip("making a temporary unprivileged user needs root")
    if not (shutil.which("useradd") and shutil.which("userdel") and shutil.which("runuser")):
        pytest.skip("making a temporary unprivileged user needs useradd, userdel, runuser")
    name = f"cmtest{secrets.token_hex(4)}"
    home = Path(tempfile.mkdtemp(prefix=f"{name}-", dir="/tmp"))
    subprocess.run(["useradd", "--system", "--no-create-home", "--home-dir", str(home),
                    "--shell", "/usr/sbin/nologin", name], check=True, capture_output=True,
                   timeout=60)
    try:
        _chown(home, name)
        user = Unprivileged(name, home)
        user.path = [_copy_sources(user)]
        user.path += [p for p in site.getsitepackages() if Path(p).is_dir()]
        python = _python_for(user)
        if python is None:
            pytest.skip(f"no Python {sys.version_info[0]}.{sys.version_info[1]} that user "
                        f"{name} may run ({sys.executable} is not readable to it)")
        user.python = python
        done = user.run([python, "-c", f"import {', '.join(NEEDED)}"], timeout=120)
        if done.returncode != 0:
            pytest.skip(f"user {name} cannot import {', '.join(NEEDED)} from "
                        f"{os.pathsep.join(user.path)}: {done.stderr.strip()[-300:]}")
        yield user
    finally:
        _remove(name, home)


def _copy_sources(user: Unprivileged) -> str:
    """``src/coolmuscle`` copied as the user's (sources only); the folder for its path."""
    src = user.home / "src"
    src.mkdir()
    shutil.copytree(ROOT / "src" / "coolmuscle", src / "coolmuscle",
                    ignore=shutil.ignore_patterns("__pycache__", "*.so"))
    _chown(src, user.name)
    return str(src)


def _remove(name: str, home: Path) -> None:
    """End the user's processes (by id), remove the user and its directory."""
    user = Unprivileged(name, home)
    with contextlib.suppress(KeyError):
        for _ in range(50):
            pids = user.processes()
            if not pids:
                break
            for pid in pids:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, signal.SIGKILL)
            time.sleep(0.1)
    subprocess.run(["userdel", name], capture_output=True, timeout=60)
    shutil.rmtree(home, ignore_errors=True)

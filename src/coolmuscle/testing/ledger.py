"""What the plug-in's fixtures made, and the check that none of it is left.

Each fixture notes what it starts (a process group, the ports it serves on, a network
namespace and its links, a pty link) in the run's :class:`Ledger`; after its teardown it
checks with :func:`leftovers` that each is gone, and ``--cm-ledger PATH`` appends the
notes to a file (one JSON object a line, safe from several xdist workers), so a check
outside the run can look again once pytest has ended.  Every process the fixtures start
carries ``COOLMUSCLE_TESTING_RUN=<token>`` in its environment: :func:`leftovers` also
looks for any process still carrying it (a grandchild that left its process group).
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import shutil
import signal
import socket
import subprocess
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

__all__ = ["Ledger", "leftovers", "TOKEN_VARIABLE"]

TOKEN_VARIABLE = "COOLMUSCLE_TESTING_RUN"
Entry = Mapping[str, Any]


class Ledger:
    """The notes of one run (``token`` names its processes)."""

    def __init__(self, token: str, path: Path | None = None) -> None:
        self.token = token
        self.path = path
        self.entries: list[dict[str, Any]] = []

    def note(self, kind: str, **what: Any) -> dict[str, Any]:
        entry = {"kind": kind, "token": self.token, **what}
        self.entries.append(entry)
        if self.path is not None:
            with self.path.open("a", encoding="utf-8") as out:
                out.write(json.dumps(entry) + "\n")
        return entry


def read_ledger(path: Path) -> list[dict[str, Any]]:
    """The notes a run appended to ``path``."""
    text = path.read_text(encoding="utf-8") if path.exists() else ""
    return [json.loads(line) for line in text.splitlines() if line.strip()]


def _process_left(entry: Entry) -> str | None:
    if not hasattr(os, "killpg"):      # no process groups (Windows): Program.close killed it
        return None
    try:
        os.killpg(int(entry["pgid"]), 0)
    except ProcessLookupError:
        return None
    except PermissionError:
        pass
    return f"process group {entry['pgid']} ({entry.get('what', 'a process')}) still runs"


def _port_left(entry: Entry) -> str | None:
    port, proto = int(entry["port"]), entry.get("proto", "tcp")
    if proto == "udp":
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            try:
                sock.bind(("127.0.0.1", port))
            except OSError as exc:
                if exc.errno == errno.EADDRINUSE:
                    return f"udp port {port} is still bound"
            return None
    with socket.socket() as sock:
        sock.settimeout(2)
        try:
            sock.connect(("127.0.0.1", port))
        except OSError:
            return None
    return f"tcp port {port} still accepts connections"


def _namespace_left(entry: Entry) -> str | None:
    if shutil.which("ip") is None:
        return None
    listed = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True,
                            timeout=20).stdout.split()
    if entry["name"] in listed:
        return f"network namespace {entry['name']} is still there"
    for link in entry.get("links", ()):
        shown = subprocess.run(["ip", "-o", "link", "show", link], capture_output=True,
                               text=True, timeout=20)
        if shown.returncode == 0:
            return f"link {link} is still there"
    return None


def _path_left(entry: Entry) -> str | None:
    path = Path(entry["path"])
    return f"{path} is still there" if path.is_symlink() or path.exists() else None


def _marked_processes(token: str) -> list[str]:
    """Processes whose environment carries ``token`` (not this one, nor its parents)."""
    mine = {os.getpid(), os.getppid()}
    found = []
    needle = f"{TOKEN_VARIABLE}={token}".encode()
    for entry in Path("/proc").iterdir() if Path("/proc").is_dir() else ():
        if not entry.name.isdigit() or int(entry.name) in mine:
            continue
        with contextlib.suppress(OSError):
            if needle in (entry / "environ").read_bytes().split(b"\0"):
                command = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(
                    errors="replace").strip()
                found.append(f"process {entry.name} ({command[:80]}) still runs")
    return found


CHECKS = {"process": _process_left, "port": _port_left, "namespace": _namespace_left,
          "path": _path_left}


def leftovers(entries: Iterable[Entry], token: str | None = None) -> list[str]:
    """What of ``entries`` is still there (and any process marked with ``token``)."""
    found = [problem for entry in entries
             if (problem := CHECKS[entry["kind"]](entry)) is not None]
    if token is not None:
        found += _marked_processes(token)
    return found


def end_group(pgid: int) -> None:
    """SIGKILL what is left of a process group (a last resort after a failed check)."""
    if hasattr(os, "killpg"):
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(pgid, signal.SIGKILL)

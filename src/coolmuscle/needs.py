"""What an optional part needs beyond a plain install: an extra, or a POSIX system.

``pip install coolmuscle`` brings what the simulator, its TCP, Modbus TCP and
EtherNet/IP front doors, the host library and the command line need (pyserial, typer,
rich).  The rest is an **extra** (pyproject.toml ``[project.optional-dependencies]``),
named when it is missing, in one line (:class:`MissingExtraError`, exit status 2 from
the ``coolmuscle`` command)::

    with needs_extra("web", "the web page"):
        from aiohttp import web

A part that needs what only some systems have (a pseudo-terminal, a raw Ethernet
socket) is imported only where it is used, and refused elsewhere with one line
(:class:`NotOnThisSystemError`, exit status 2): :func:`needs_posix`,
:func:`needs_af_packet`.  What only makes a part late under load where it is missing
(real-time scheduling) is said once: :func:`realtime_problem`.  What is asked is the
capability itself (can the modules be imported, does ``socket`` have the constant, can
a thread be scheduled so), not the system's name.

Standard library and :mod:`coolmuscle.errors` only: every layer may use it.
"""

from __future__ import annotations

import importlib
import socket
from collections.abc import Iterator
from contextlib import contextmanager

from .errors import CoolMuscleError

#: Each extra (pyproject.toml) and the top-level modules of it that coolmuscle imports.
EXTRAS: dict[str, tuple[str, ...]] = {
    "plot": ("matplotlib", "numpy"),
    "web": ("aiohttp",),
    "term": ("prompt_toolkit",),
    "twin": ("numpy", "scipy", "tomlkit", "matplotlib"),
    "dask": ("dask", "distributed"),
}

#: What a pseudo-terminal needs (``os.openpty`` aside): Windows has none of them.
PTY_MODULES = ("termios", "tty", "fcntl")


class MissingExtraError(CoolMuscleError, ImportError):
    """An optional part whose libraries are not installed; names the extra to install."""

    def __init__(self, what: str, extra: str, module: str) -> None:
        super().__init__(f"{what} needs the '{extra}' extra ({module} is not installed): "
                         f'pip install "coolmuscle[{extra}]"', name=module)
        self.extra = extra
        self.what = what


class NotOnThisSystemError(CoolMuscleError, OSError):
    """A part this operating system cannot run (a pty on Windows, AF_PACKET off Linux)."""


@contextmanager
def needs_extra(extra: str, what: str) -> Iterator[None]:
    """Imports inside the block that fail for want of one of ``extra``'s modules raise
    :class:`MissingExtraError` naming ``what`` and the extra; any other import error
    (a bug, a broken install of something else) goes on as it is."""
    try:
        yield
    except ModuleNotFoundError as exc:
        root = (exc.name or "").partition(".")[0]
        if root in EXTRAS[extra]:
            raise MissingExtraError(what, extra, root) from None
        raise


def has_extra(extra: str) -> bool:
    """Every module of ``extra`` can be found (nothing is imported)."""
    from importlib.util import find_spec

    return all(find_spec(name) is not None for name in EXTRAS[extra])


def require_extra(extra: str, what: str) -> None:
    """:class:`MissingExtraError` now, before any work, when a module of ``extra`` is
    not installed (for a part imported only at the end, as a plot after a run)."""
    from importlib.util import find_spec

    for name in EXTRAS[extra]:
        if find_spec(name) is None:
            raise MissingExtraError(what, extra, name)


#: What to use instead of a POSIX-only option on Windows, by default.
INSTEAD = ("--rfc2217 [HOST:]PORT (a COM port to rfc2217:// clients and virtual COM port "
           "tools) or --tcp (README.md \"Windows\")")


def posix_terminals() -> bool:
    """This system has pseudo-terminals and terminal attributes (POSIX: Linux, macOS)."""
    import os

    try:
        for name in PTY_MODULES:
            importlib.import_module(name)
    except ImportError:
        return False
    return hasattr(os, "openpty")


def needs_posix(option: str, instead: str = INSTEAD) -> None:
    """``option`` needs pseudo-terminals, terminal attributes or file descriptors the
    event loop can wait on (a pty, a serial device, standard input):
    :class:`NotOnThisSystemError` naming ``instead`` where they are missing (Windows)."""
    if not posix_terminals():
        raise NotOnThisSystemError(
            f"{option} needs a POSIX system (Linux, macOS); on Windows use {instead}")


def needs_af_packet(option: str) -> None:
    """``option`` sends raw Ethernet frames: :class:`NotOnThisSystemError` where there is
    no ``AF_PACKET`` socket (Windows, macOS)."""
    if not hasattr(socket, "AF_PACKET"):
        raise NotOnThisSystemError(
            f"{option} needs Linux (a raw AF_PACKET socket for the EtherCAT frames)")


def realtime_problem() -> str | None:
    """Why a thread cannot run under ``SCHED_FIFO`` here (asked by trying it in a thread
    that then ends), or ``None`` when it can: a front end that answers in real time (the
    EtherCAT bridge) then runs at normal priority and says so once."""
    import os
    import threading

    setter = getattr(os, "sched_setscheduler", None)
    if setter is None:
        return "this system has no SCHED_FIFO"
    refused: list[OSError] = []

    def probe() -> None:
        try:
            setter(0, os.SCHED_FIFO, os.sched_param(1))
        except OSError as exc:
            refused.append(exc)
    thread = threading.Thread(target=probe, name="coolmuscle-realtime-probe")
    thread.start()
    thread.join()
    if refused:
        return ("SCHED_FIFO needs the machine's CAP_SYS_NICE (root) or a real-time "
                "priority limit (ulimit -r)")
    return None

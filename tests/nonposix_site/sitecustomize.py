"""A Python without the POSIX-only parts, as on Windows (tests/test_nonposix.py).

Put this folder first on ``PYTHONPATH`` and every interpreter started with that
environment (the ``coolmuscle`` command, the sims it starts, a process pool's workers)
loads this module at start-up (``site`` imports ``sitecustomize``), before anything
of coolmuscle:

* the modules Windows does not have cannot be imported (:data:`BLOCKED`: ``fcntl``,
  ``termios``, ``pty``, ``tty``, ``resource``, ``pwd``, ``grp``): a finder first on
  ``sys.meta_path`` raises ``ModuleNotFoundError`` for them, and any already loaded
  leaves ``sys.modules``;
* the functions and constants Windows does not have are gone (:data:`MISSING`:
  ``socket.AF_PACKET``, ``os.getuid``, ``os.setsid``, ``os.killpg``, ``os.openpty``,
  ``os.sched_setscheduler``, ``signal.SIGHUP``, ``signal.pthread_sigmask`` ...);
* ``multiprocessing`` offers only the ``spawn`` start method, as on Windows.

Libraries that choose their back end by platform are loaded first, while the modules
are still there: pyserial (whose POSIX port module imports ``fcntl`` and ``termios``;
on Windows it loads its Win32 module instead).  What they imported is only theirs:
coolmuscle's own imports meet the blocked modules.

``COOLMUSCLE_NONPOSIX_CHECK=1`` prints ``blocked`` when the bootstrap is in place (the
test checks that it is, in the processes it starts).
"""

from __future__ import annotations

import importlib.abc
import os
import signal
import socket
import sys

#: Modules a Windows Python does not have.
BLOCKED = frozenset({"fcntl", "termios", "pty", "tty", "resource", "pwd", "grp"})

#: Attributes a Windows Python does not have, by module.
MISSING = {
    os: ("getuid", "geteuid", "getgid", "getegid", "setsid", "killpg", "getpgid", "setpgrp",
         "openpty", "sched_setscheduler", "sched_getscheduler", "sched_param",
         "SCHED_FIFO", "SCHED_RR", "mkfifo", "getloadavg"),
    signal: ("SIGHUP", "SIGQUIT", "SIGUSR1", "SIGUSR2", "SIGALRM", "SIGTSTP", "SIGCONT",
             "SIGWINCH", "pthread_sigmask", "pthread_kill", "siginterrupt", "setitimer",
             "alarm", "pause", "sigwait"),
    # (socket.AF_UNIX stays: socket.socketpair, which asyncio's loop needs, takes it as
    # its default here, and Windows builds of Python have a socketpair of their own)
    socket: ("AF_PACKET", "PF_PACKET"),
}

# loaded before the blockers: they pick their back end by platform (see above)
import serial  # noqa: E402,F401


class _Blocker(importlib.abc.MetaPathFinder):
    """No spec for a blocked module: ``import fcntl`` fails as it does on Windows."""

    def find_spec(self, fullname: str, path: object, target: object = None) -> None:
        if fullname in BLOCKED:
            raise ModuleNotFoundError(f"No module named {fullname!r} (not on Windows)",
                                      name=fullname)
        return None


def _install() -> None:
    sys.meta_path.insert(0, _Blocker())
    for name in BLOCKED:
        sys.modules.pop(name, None)
    for module, names in MISSING.items():
        for name in names:
            if hasattr(module, name):
                delattr(module, name)
    # multiprocessing as on Windows: only "spawn" (get_context("forkserver") is a
    # ValueError there); its module functions are bound to this one default context
    import multiprocessing.context as mp_context

    concrete = mp_context._concrete_contexts
    for method in ("fork", "forkserver"):
        concrete.pop(method, None)
    default = mp_context._default_context
    default._default_context = concrete["spawn"]
    import multiprocessing

    default.get_all_start_methods = multiprocessing.get_all_start_methods = lambda: ["spawn"]
    if os.environ.get("COOLMUSCLE_NONPOSIX_CHECK") == "1":
        print("blocked", flush=True)


_install()

"""``cm_lab``: an EtherCAT lab for one test, a veth pair with the bridge on its far end.

The one place that knows how a lab is made: :func:`unavailable` says why none can be
(the clear reason a test is skipped with), :func:`open_lab` makes one and removes it
again.  Today a lab needs root: a veth pair whose slave end is moved into a network
namespace of its own, where ``coolmuscle sim --ethercat`` serves the bridge
(frontends/ethercat/lab.py; docs/ethercat.md), while the master's end stays with the
test.  A rootless lab (a user namespace) changes :func:`unavailable` and
:attr:`LabLink.slave_prefix` here and nothing else.
"""

from __future__ import annotations

import os
import shutil
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

__all__ = ["LabLink", "LabUnavailable", "unavailable", "open_lab"]


class LabUnavailable(RuntimeError):
    """A lab this machine cannot make (the message is the reason to skip with)."""


@dataclass(frozen=True)
class LabLink:
    """A lab's link: the master's interface here, the slave's in ``namespace``."""

    namespace: str
    master_if: str
    slave_if: str

    @property
    def slave_prefix(self) -> list[str]:
        """The command that runs a program on the slave's side of the link."""
        return ["ip", "netns", "exec", self.namespace]


def unavailable() -> str | None:
    """Why no lab can be made here, or ``None``."""
    if not sys.platform.startswith("linux"):
        return "the EtherCAT lab needs Linux (veth pairs and network namespaces)"
    if shutil.which("ip") is None:
        return "the EtherCAT lab needs the 'ip' command (iproute2)"
    if os.geteuid() != 0:
        return ("the EtherCAT lab needs root (veth pairs and network namespaces); "
                "run the tests as root to include it")
    return None


@contextmanager
def open_lab(prefix: str) -> Iterator[LabLink]:
    """A lab named from ``prefix`` (at most 11 characters: interface names end in
    ``m``/``s`` and have 15 at most); removed afterwards, whatever happened.
    :class:`LabUnavailable` when it cannot be made."""
    reason = unavailable()
    if reason is not None:
        raise LabUnavailable(reason)
    from ..frontends.ethercat.lab import Lab, LabError, create, destroy
    lab = Lab(f"{prefix}ns", f"{prefix}m", f"{prefix}s", inside="slave")
    destroy(lab, mark=prefix)                   # left over from a killed run
    try:
        create(lab, mark=prefix)
    except LabError as exc:
        raise LabUnavailable(f"the EtherCAT lab could not be made: {exc}") from None
    try:
        yield LabLink(lab.namespace, lab.master_if, lab.slave_if)
    finally:
        destroy(lab, mark=prefix)

"""``cm_lab``: an EtherCAT lab for one test, a veth pair with the bridge on its far end.

The one place that knows how a lab is made: :func:`unavailable` says why none can be
(the clear reason a test is skipped with), :func:`open_lab` makes one and removes it
again, and :attr:`LabLink.slave_prefix` is how the bridge is started on its end.

* **root**: a veth pair whose slave end is moved into a network namespace of its own,
  where ``coolmuscle sim --ethercat`` serves the bridge (``ip netns exec``;
  frontends/ethercat/lab.py; docs/ethercat.md), while the master's end stays with the
  test;
* **without root**: the test's master must be in the lab's namespace, so the tests run
  in one: ``coolmuscle ethercat lab run --no-sim -- pytest ...`` puts pytest in a user
  and network namespace of its own, where it is root of the namespace; the pair is
  made there with both ends in that namespace, the bridge started on one end without
  a prefix and the test's master on the other.  Outside such a namespace an
  unprivileged run is skipped with the command to use (or, where the kernel refuses
  user namespaces, what to enable).
"""

from __future__ import annotations

import os
import shutil
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

__all__ = ["LabLink", "LabUnavailable", "unavailable", "open_lab", "RUN_INSIDE"]

#: How an unprivileged user runs the tests in a lab of their own (docs/ethercat.md).
RUN_INSIDE = "coolmuscle ethercat lab run --no-sim -- pytest ..."


class LabUnavailable(RuntimeError):
    """A lab this machine cannot make (the message is the reason to skip with)."""


@dataclass(frozen=True)
class LabLink:
    """A lab's link: the master's interface here, the slave's in ``namespace`` (``None``:
    both ends here, in the namespace the tests run in)."""

    namespace: str | None
    master_if: str
    slave_if: str

    @property
    def slave_prefix(self) -> list[str]:
        """The command that runs a program on the slave's side of the link."""
        return ["ip", "netns", "exec", self.namespace] if self.namespace else []


def _own_namespace() -> bool:
    """Root of a user namespace below the machine's (``lab run``, ``unshare -Urn``)."""
    from ..frontends.ethercat.lab import in_user_namespace
    return hasattr(os, "geteuid") and os.geteuid() == 0 and in_user_namespace()


def unavailable() -> str | None:
    """Why no lab can be made here, or ``None``."""
    if not sys.platform.startswith("linux"):
        return "the EtherCAT lab needs Linux (veth pairs and network namespaces)"
    if shutil.which("ip") is None:
        return "the EtherCAT lab needs the 'ip' command (iproute2)"
    from ..frontends.ethercat.lab import privileged, userns_problem
    if privileged() or _own_namespace():
        return None
    problem = userns_problem()
    if problem is not None:
        return (f"the EtherCAT lab needs root or a user namespace of its own, and {problem}; "
                "or run the tests as root")
    return ("the EtherCAT lab needs root, or a network namespace of its own that the "
            f"test's master shares: without root run the tests in one: {RUN_INSIDE}")


@contextmanager
def open_lab(prefix: str) -> Iterator[LabLink]:
    """A lab named from ``prefix`` (at most 11 characters: interface names end in
    ``m``/``s`` and have 15 at most); removed afterwards, whatever happened.
    :class:`LabUnavailable` when it cannot be made."""
    reason = unavailable()
    if reason is not None:
        raise LabUnavailable(reason)
    from ..frontends.ethercat.lab import (
        Lab,
        LabError,
        create,
        create_here,
        destroy,
        destroy_here,
        privileged,
    )
    here = not privileged()
    lab = Lab("" if here else f"{prefix}ns", f"{prefix}m", f"{prefix}s", inside="slave")
    make, remove = (create_here, destroy_here) if here else (create, destroy)
    remove(lab, mark=prefix)                    # left over from a killed run
    try:
        make(lab, mark=prefix)
    except LabError as exc:
        raise LabUnavailable(f"the EtherCAT lab could not be made: {exc}") from None
    try:
        yield LabLink(None if here else lab.namespace, lab.master_if, lab.slave_if)
    finally:
        remove(lab, mark=prefix)

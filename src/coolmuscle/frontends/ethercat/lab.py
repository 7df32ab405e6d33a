"""A virtual Ethernet link for trying the bridge without hardware (``coolmuscle ethercat lab``).

``up`` makes a veth pair: one end (the master's) stays in the current network
namespace, the other (the slave's) moves into a new namespace, so frames cross a
real link.  Both ends carry the alias ``coolmuscle-lab`` and ``down`` removes only
links and namespaces carrying that mark.  Needs root (``ip`` from iproute2).

The same helpers make the per-test links of the test suite (:func:`veth_pair`).
"""

from __future__ import annotations

import contextlib
import logging
import shutil
import subprocess
from collections.abc import Iterator
from dataclasses import dataclass

log = logging.getLogger(__name__)

MARK = "coolmuscle-lab"
DEFAULT_NAMESPACE = "coolmuscle-lab"
DEFAULT_MASTER_IF = "cmlab-master"
DEFAULT_SLAVE_IF = "cmlab-slave"


class LabError(RuntimeError):
    """An ``ip`` command failed (its message says why)."""


@dataclass(frozen=True)
class Lab:
    """A veth pair: ``master_if`` here, ``slave_if`` inside ``namespace`` (or the
    other way round when ``inside`` is ``"master"``, as the tests use it)."""

    namespace: str
    master_if: str
    slave_if: str
    inside: str = "slave"

    @property
    def inner(self) -> str:
        return self.slave_if if self.inside == "slave" else self.master_if

    @property
    def outer(self) -> str:
        return self.master_if if self.inside == "slave" else self.slave_if

    def instructions(self, program: str = "coolmuscle") -> str:
        """What to run next; ``program`` is the command as it runs under sudo (sudo
        does not keep an activated virtual environment: ``.venv/bin/coolmuscle``)."""
        return (f"EtherCAT lab up: veth {self.master_if} <-> {self.slave_if} "
                f"(in network namespace {self.namespace})\n"
                f"  slave:  sudo ip netns exec {self.namespace} {program} sim --ethercat "
                f"{self.slave_if} [--bridge EB02]\n"
                f"  master: give your EtherCAT master the interface {self.master_if} "
                f"(e.g. pysoem: master.open('{self.master_if}'))\n"
                f"  down:   sudo {program} ethercat lab down")


def ip(*args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
    """Run ``ip ARGS``; raise :class:`LabError` with ip's message on failure."""
    exe = shutil.which("ip")
    if exe is None:
        raise LabError("the 'ip' command (iproute2) is not installed")
    done = subprocess.run([exe, *args], capture_output=True, text=True, timeout=20)
    if check and done.returncode != 0:
        raise LabError(f"ip {' '.join(args)}: {done.stderr.strip() or done.returncode}")
    return done


def _quiet(namespace: str | None, iface: str) -> None:
    """No IPv6 chatter on the link (only EtherCAT frames cross it)."""
    path = f"/proc/sys/net/ipv6/conf/{iface}/disable_ipv6"
    cmd = ["sh", "-c", f"test -w {path} && echo 1 > {path} || true"]
    if namespace:
        ip("netns", "exec", namespace, *cmd, check=False)
    else:
        subprocess.run(cmd, capture_output=True, timeout=10, check=False)


def create(lab: Lab, *, mark: str = MARK) -> Lab:
    """Make the pair and the namespace; on failure remove what was made."""
    ip("netns", "add", lab.namespace)
    try:
        ip("link", "add", lab.outer, "type", "veth", "peer", "name", lab.inner)
        ip("link", "set", lab.outer, "alias", mark)
        ip("link", "set", lab.inner, "alias", mark)
        ip("link", "set", lab.inner, "netns", lab.namespace)
        _quiet(None, lab.outer)
        _quiet(lab.namespace, lab.inner)
        ip("link", "set", lab.outer, "up")
        ip("netns", "exec", lab.namespace, "ip", "link", "set", lab.inner, "up")
        ip("netns", "exec", lab.namespace, "ip", "link", "set", "lo", "up")
    except BaseException:
        destroy(lab, mark=mark)
        raise
    return lab


def _marked(namespace: str | None, iface: str, mark: str) -> bool:
    args = ("netns", "exec", namespace, "ip", "-o", "link", "show", iface) if namespace \
        else ("-o", "link", "show", iface)
    done = ip(*args, check=False)
    return done.returncode == 0 and f"alias {mark}" in done.stdout


def destroy(lab: Lab, *, mark: str = MARK) -> list[str]:
    """Remove the pair and the namespace if they carry ``mark``; returns what was removed."""
    removed = []
    if _marked(None, lab.outer, mark):
        ip("link", "del", lab.outer, check=False)
        removed.append(lab.outer)
    namespaces = ip("netns", "list", check=False).stdout.split()
    if lab.namespace in namespaces:
        if _marked(lab.namespace, lab.inner, mark) or lab.outer in removed:
            ip("netns", "exec", lab.namespace, "ip", "link", "del", lab.inner, check=False)
            ip("netns", "del", lab.namespace, check=False)
            removed.append(lab.namespace)
    return removed


def up(namespace: str = DEFAULT_NAMESPACE, master_if: str = DEFAULT_MASTER_IF,
       slave_if: str = DEFAULT_SLAVE_IF) -> Lab:
    """``coolmuscle ethercat lab up``; a lab that is up already, or a name taken by
    something else, is one :class:`LabError` line saying so (not ip's "File exists")."""
    lab = Lab(namespace, master_if, slave_if)
    in_use = _in_use(lab)
    if in_use:
        raise LabError(in_use)
    return create(lab)


def _in_use(lab: Lab) -> str:
    """Why ``lab`` cannot be made now ("": it can)."""
    namespaces = ip("netns", "list", check=False).stdout.split()
    ours = _marked(None, lab.outer, MARK)
    if lab.namespace in namespaces and ours and _marked(lab.namespace, lab.inner, MARK):
        return (f"the EtherCAT lab is up already: veth {lab.master_if} <-> {lab.slave_if} "
                f"(in network namespace {lab.namespace}); 'sudo coolmuscle ethercat lab "
                "down' removes it")
    if lab.namespace in namespaces:
        return (f"network namespace {lab.namespace} exists already"
                + (" (a lab half made: 'sudo coolmuscle ethercat lab down' removes it)"
                   if ours else ", not made by the lab: give another with --namespace"))
    if ip("-o", "link", "show", lab.outer, check=False).returncode == 0:
        return (f"interface {lab.outer} exists already"
                + (" (a lab half made: 'sudo coolmuscle ethercat lab down' removes it)"
                   if ours else ", not made by the lab: give another with --master-if"))
    return ""


def down(namespace: str = DEFAULT_NAMESPACE, master_if: str = DEFAULT_MASTER_IF,
         slave_if: str = DEFAULT_SLAVE_IF) -> list[str]:
    """``coolmuscle ethercat lab down``: only what ``up`` made."""
    return destroy(Lab(namespace, master_if, slave_if))


@contextlib.contextmanager
def veth_pair(prefix: str, inside: str = "master") -> Iterator[Lab]:
    """A lab with names from ``prefix`` for one test; always deleted afterwards."""
    lab = Lab(f"{prefix}ns", f"{prefix}m", f"{prefix}s", inside)
    destroy(lab, mark=prefix)          # left over from a killed run
    create(lab, mark=prefix)
    try:
        yield lab
    finally:
        destroy(lab, mark=prefix)

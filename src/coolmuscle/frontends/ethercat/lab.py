"""A virtual Ethernet link for trying the bridge without hardware (``coolmuscle ethercat lab``).

``up`` makes a veth pair: one end (the master's) stays in the current network
namespace, the other (the slave's) moves into a new namespace, so frames cross a
real link.  Both ends carry the alias ``coolmuscle-lab`` and ``down`` removes only
links and namespaces carrying that mark.  Needs root (``ip`` from iproute2).

Without root (``coolmuscle ethercat lab run``): :func:`enter_namespace` moves this
process into a user namespace of its own (where it is root, mapped to the user) and a
network namespace owned by it (unshare(2) with ``CLONE_NEWUSER | CLONE_NEWNET``), and
:func:`create_here` makes the pair there, both ends in that one namespace: the bridge
on one end and the master on the other are both inside, and a raw socket works there
(``CAP_NET_RAW`` of the namespace).  Everything goes with the namespace's last
process.  :func:`userns_problem` says why a kernel refuses it.

The same helpers make the per-test links of the test suite (:func:`veth_pair`) and of
the pytest plug-in's ``cm_lab`` (coolmuscle.testing.lab).
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import logging
import os
import shutil
import subprocess
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

log = logging.getLogger(__name__)

#: unshare(2) flags (linux/sched.h), for Pythons before 3.12's ``os.unshare``.
CLONE_NEWNET = 0x40000000
CLONE_NEWUSER = 0x10000000

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


def create_here(lab: Lab, *, mark: str = MARK) -> Lab:
    """Make the pair with both ends in the current network namespace (a namespace of
    this process's own: :func:`enter_namespace`); on failure remove what was made."""
    ip("link", "set", "lo", "up")
    ip("link", "add", lab.master_if, "type", "veth", "peer", "name", lab.slave_if)
    try:
        for iface in (lab.master_if, lab.slave_if):
            ip("link", "set", iface, "alias", mark)
            _quiet(None, iface)
            ip("link", "set", iface, "up")
    except BaseException:
        destroy_here(lab, mark=mark)
        raise
    return lab


def destroy_here(lab: Lab, *, mark: str = MARK) -> list[str]:
    """Remove the pair :func:`create_here` made (it carries ``mark``)."""
    removed = []
    for iface in (lab.master_if, lab.slave_if):
        if _marked(None, iface, mark):
            ip("link", "del", iface, check=False)       # the peer goes with it
            removed.append(iface)
            break
    return removed


def in_user_namespace() -> bool:
    """This process is in a user namespace below the first (its root is not the
    machine's): the first maps every id to itself (user_namespaces(7))."""
    try:
        first = Path("/proc/self/uid_map").read_text().split()
    except OSError:
        return False
    return first[:3] != ["0", "0", "4294967295"]


def privileged() -> bool:
    """Root of the machine: ``ip netns`` and a veth pair across namespaces work."""
    return hasattr(os, "geteuid") and os.geteuid() == 0 and not in_user_namespace()


def _sysctl(name: str) -> int | None:
    try:
        return int(Path("/proc/sys", *name.split(".")).read_text().strip())
    except (OSError, ValueError):
        return None


def userns_problem() -> str | None:
    """Why this kernel will not give an unprivileged user a user namespace, or ``None``
    (read from its settings; :func:`enter_namespace` finds the rest)."""
    if _sysctl("user.max_user_namespaces") == 0:
        return ("this kernel allows no user namespaces (user.max_user_namespaces=0); "
                "root enables them: sysctl -w user.max_user_namespaces=15000")
    if _sysctl("kernel.unprivileged_userns_clone") == 0:
        return ("this kernel refuses user namespaces to unprivileged users "
                "(kernel.unprivileged_userns_clone=0); root enables them: "
                "sysctl -w kernel.unprivileged_userns_clone=1")
    if _sysctl("kernel.apparmor_restrict_unprivileged_userns") == 1:
        return ("AppArmor keeps capabilities from unprivileged user namespaces "
                "(kernel.apparmor_restrict_unprivileged_userns=1); root allows them: "
                "sysctl -w kernel.apparmor_restrict_unprivileged_userns=0")
    return None


def _unshare(flags: int) -> None:
    unshare = getattr(os, "unshare", None)
    if unshare is not None:                      # Python 3.12 and later
        unshare(flags)
        return
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.unshare(ctypes.c_int(flags)) != 0:
        code = ctypes.get_errno()
        raise OSError(code, os.strerror(code))


def enter_namespace() -> bool:
    """Move this process (it must have one thread) into a network namespace of its own:
    root of the machine keeps its user namespace, anyone else gets a user namespace of
    its own too, where it is root mapped to itself.  Whether a user namespace was made;
    :class:`LabError` saying what is missing when the kernel refuses."""
    user = not privileged()
    uid, gid = os.getuid(), os.getgid()
    try:
        _unshare(CLONE_NEWNET | (CLONE_NEWUSER if user else 0))
    except OSError as exc:
        raise LabError(_refused(exc, user)) from None
    if user:
        try:
            Path("/proc/self/setgroups").write_text("deny")
            Path("/proc/self/uid_map").write_text(f"0 {uid} 1")
            Path("/proc/self/gid_map").write_text(f"0 {gid} 1")
        except OSError as exc:
            raise LabError(f"cannot map this user into its namespace: {exc}") from None
    return user


def _refused(exc: OSError, user: bool) -> str:
    what = "a user and network namespace" if user else "a network namespace"
    reason = userns_problem() if user else None
    if exc.errno == errno.EINVAL and user:
        reason = "this process runs several threads (unshare(2) needs one)"
    elif exc.errno == errno.ENOSPC:
        reason = reason or ("no user namespace left (user.max_user_namespaces reached); "
                            "root raises it: sysctl -w user.max_user_namespaces=15000")
    return f"cannot make {what}: {exc.strerror or exc}" + (f": {reason}" if reason else "")


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

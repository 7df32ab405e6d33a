"""``coolmuscle ethercat ...`` (lab up/down/run, esi) and the ``sim --ethercat`` helpers.

Registered on the main command in :mod:`coolmuscle.tools.cli.app` with ``add_typer``.
The bridge is :mod:`coolmuscle.frontends.ethercat` (docs/ethercat.md): the ESI file
comes from its description, the lab and the transport are its I/O.  ``sim --ethercat``
serves one bridge (``--bridge``) or several in a line (``--bridges``, or a machine
file's ``[ethercat] bridges``): :func:`segment_codes` decides which, and
:func:`bridge_chains` makes the chain behind each further bridge, with its own state
folder and its part of the machine file.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING, Literal, NoReturn, overload

import typer

from ...device.wire.vocabulary import MAX_BRIDGES
from ...errors import CoolMuscleError
from ...frontends.ethercat.bridge import identity as ident

if TYPE_CHECKING:
    from ...chain.machine import Machine
    from ...device.api import ChainFactory, Device
    from ...frontends.ethercat.lab import Lab
    from ...frontends.ethercat.transport import BridgeChains, EthercatTransport
    from ...sim.kernel import Kernel

app = typer.Typer(name="ethercat", no_args_is_help=True,
                  help="The EtherCAT Cool Muscle Bridge: lab link and ESI file (docs/ethercat.md).")
lab_app = typer.Typer(name="lab", no_args_is_help=True,
                      help="A veth pair for trying the bridge without hardware: up/down "
                           "(root), or run a master in a lab of its own (no root needed).")
app.add_typer(lab_app)


class EthercatUsageError(CoolMuscleError, ValueError):
    """Bad --ethercat / --bridge options (exit status 2)."""


def chain_firmware(bridge: str) -> str:
    """The Chain firmware string of a bridge variant ("cm1,cm1,cm2,cm2" for EB12)."""
    try:
        v = ident.variant(bridge)
    except ValueError as exc:
        raise EthercatUsageError(str(exc)) from None
    return ",".join(v.firmware)


def segment_codes(bridge: str | None, bridges: str | None,
                  machine: Machine | None = None) -> tuple[str, ...]:
    """The bridges of ``sim --ethercat`` in line order: ``--bridges EB02,EB12``, else
    ``--bridge``, else the machine file's ``[ethercat] bridges``, else one EB02."""
    if bridge is not None and bridges is not None:
        raise EthercatUsageError("--bridge and --bridges exclude each other "
                                 "(--bridges EB02 is one bridge)")
    if bridges is not None:
        names = [b.strip() for b in bridges.split(",")]
        where = "--bridges"
    elif bridge is not None:
        names, where = [bridge], "--bridge"
    elif machine is not None and machine.bridges:
        names, where = list(machine.bridges), f"{machine.source}: [ethercat] bridges"
    else:
        names, where = [ident.DEFAULT_VARIANT], "--bridge"
    if not names or not all(names):
        raise EthercatUsageError(f"{where}: a comma-separated list of bridges, "
                                 "e.g. EB02,EB02,EB12")
    if len(names) > MAX_BRIDGES:
        raise EthercatUsageError(f"{where}: {len(names)} bridges; a segment has at most "
                                 f"{MAX_BRIDGES}")
    try:
        codes = tuple(ident.variant(name).code for name in names)
    except ValueError as exc:
        raise EthercatUsageError(f"{where}: {exc}") from None
    if machine is not None:
        beyond = [a for a in machine.axes if a.bridge > len(codes)]
        if beyond:
            raise EthercatUsageError(
                f"{machine.source}: axis motor={beyond[0].motor} is on bridge "
                f"{beyond[0].bridge}, and the segment has {len(codes)}")
    return codes


def bridge_chains(factory: ChainFactory, state: Path | None, pace: bool,
                  machine: Machine | None) -> BridgeChains:
    """What makes the chain behind bridge n >= 2 of ``sim --ethercat``: four motors with
    the variant's firmware on the segment's kernel, its state in ``STATE/bridge-n``,
    its ``[[axis]]`` tables of the machine file."""
    def make(kernel: Kernel, position: int, firmware: str) -> Device:
        folder = None
        if state is not None:
            folder = state / f"bridge-{position}"
            folder.mkdir(parents=True, exist_ok=True)
        extra = {} if machine is None else {"machine": machine.for_bridge(position)}
        return factory(kernel, 4, firmware=firmware, state_dir=folder, pacing=pace, **extra)
    return make


def sim_transport(iface: str, codes: tuple[str, ...],
                  chains: BridgeChains | None = None) -> EthercatTransport:
    """The transport of ``sim --ethercat IFACE`` for bridges ``codes`` (checks the
    interface)."""
    from ...frontends.ethercat.transport import EthercatTransport
    from ...needs import needs_af_packet
    needs_af_packet("--ethercat")
    return EthercatTransport(iface, bridges=codes, chains=chains)


#: The lab's options, shared by ``up`` and ``down`` (the same names remove what up made).
_NAMESPACE = typer.Option("coolmuscle-lab", "--namespace", help="Network namespace.")
_MASTER_IF = typer.Option("cmlab-master", "--master-if", help="The master's end.")
_SLAVE_IF = typer.Option("cmlab-slave", "--slave-if",
                         help="The slave's end (inside the namespace).")


def _fail(text: str, code: int) -> NoReturn:
    typer.echo(f"coolmuscle: {text}", err=True)
    raise typer.Exit(code)


@overload
def _lab(step: Literal["up"], namespace: str, master_if: str, slave_if: str) -> Lab: ...


@overload
def _lab(step: Literal["down"], namespace: str, master_if: str, slave_if: str) -> list[str]: ...


def _lab(step: str, namespace: str, master_if: str, slave_if: str) -> Lab | list[str]:
    """``lab.up`` or ``lab.down`` with the lab's options (loaded only now: it needs
    root's tools); a ``LabError`` is one line and exit status 1."""
    from ...frontends.ethercat import lab
    from ...needs import needs_af_packet
    needs_af_packet("coolmuscle ethercat lab")
    if not lab.privileged():
        _fail(f"ethercat lab {step} needs root (a network namespace for the slave's end); "
              "without root run the master in a lab of its own: coolmuscle ethercat lab "
              "run -- COMMAND (docs/ethercat.md)", 1)
    run = lab.up if step == "up" else lab.down
    try:
        return run(namespace, master_if, slave_if)
    except lab.LabError as exc:
        _fail(str(exc), 1)


def _program() -> str:
    """This command as a path sudo finds: sudo does not keep an activated virtual
    environment, so ``coolmuscle`` alone may be another one, or none."""
    import os
    import shlex
    import sys
    run = sys.argv[0] if sys.argv else ""
    if os.path.basename(run) == "coolmuscle" and os.path.isabs(run):
        return shlex.quote(run)
    return f"{shlex.quote(sys.executable)} -m coolmuscle"


@lab_app.command("up")
def lab_up(
    namespace: str = _NAMESPACE,
    master_if: str = _MASTER_IF,
    slave_if: str = _SLAVE_IF,
) -> None:
    """Make the veth pair and print which end to give the master."""
    typer.echo(_lab("up", namespace, master_if, slave_if).instructions(_program()))


@lab_app.command("down")
def lab_down(
    namespace: str = _NAMESPACE,
    master_if: str = _MASTER_IF,
    slave_if: str = _SLAVE_IF,
) -> None:
    """Remove the pair and the namespace that ``up`` made (nothing else)."""
    removed = _lab("down", namespace, master_if, slave_if)
    typer.echo("removed: " + ", ".join(removed) if removed else "nothing to remove")


@lab_app.command("run")
def lab_run(
    command: list[str] = typer.Argument(..., metavar="-- COMMAND [ARGS]...",
                                        help="The master to run, on the master's end."),
    bridge: str = typer.Option("EB02", "--bridge", metavar="EB01|EB02|EB12",
                               help="Bridge variant the lab's sim serves."),
    no_sim: bool = typer.Option(False, "--no-sim",
                                help="Make the link only (COMMAND starts its own sim)."),
    state: Path | None = typer.Option(None, "--state", metavar="DIR",
                                      help="State directory of the sim (default: none)."),
    master_if: str = _MASTER_IF,
    slave_if: str = typer.Option("cmlab-slave", "--slave-if", help="The slave's end."),
) -> None:
    """Run COMMAND in a lab of its own: a network namespace (and, without root, a user
    namespace) with the veth pair, the bridge on one end, COMMAND on the other
    ($COOLMUSCLE_LAB_MASTER_IF); all gone when COMMAND ends, with its exit status."""
    from ...frontends.ethercat.lab import LabError
    from ...needs import needs_af_packet
    from .labrun import run_lab
    needs_af_packet("coolmuscle ethercat lab run")
    try:
        chain_firmware(bridge)
    except EthercatUsageError as exc:
        _fail(f"--bridge: {exc}", 2)
    try:
        code = run_lab(command, bridge=ident.variant(bridge).code, sim=not no_sim,
                       state=state, master_if=master_if, slave_if=slave_if,
                       say=lambda line: typer.echo(line, err=True))
    except LabError as exc:
        _fail(str(exc), 1)
    raise typer.Exit(code)


@app.command("esi")
def esi(
    bridge: list[str] = typer.Option(list(ident.VARIANTS), "--bridge",
                                     help="Variants to describe (default: all)."),
) -> None:
    """Write the ESI file (ETG.2000 XML) to stdout: ``> CoolMuscleBridge.xml``."""
    from ...frontends.ethercat.bridge.esi import esi_text
    try:
        codes = tuple(ident.variant(b).code for b in bridge)
    except ValueError as exc:
        _fail(str(exc), 2)
    sys.stdout.write(esi_text(codes))

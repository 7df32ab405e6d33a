"""The ``coolmuscle`` command (typer + rich): ``sim`` and ``run``.

Owns command-line parsing, the ready banner, signal handling and the mapping of
errors to one-line messages and exit codes.  No traceback reaches the user
(set ``COOLMUSCLE_DEBUG=1`` to see one):

* 0 success; 1 a failed run (expectation mismatch, ``@until`` timeout, model error)
  or a runtime error (port in use, store); 2 bad usage or a bad script;
  70 an internal error (a bug: please report it).

``sim`` serves a virtual chain over TCP / a pty / stdio in real time until Ctrl-C or
SIGTERM (docs/transports.md); ``run`` plays a script in fast virtual time and checks
its expectations (docs/scripts.md); ``check``, ``upload`` and ``term`` are the host
tools of :mod:`coolmuscle.tools` (docs/user-guide.md).
"""

from __future__ import annotations

import asyncio
import enum
import logging
import os
import signal
import sys
import traceback
from pathlib import Path
from typing import Any, Callable, Optional

import typer
from rich.console import Console

from .. import __version__
from ..errors import CoolMuscleError, TransportError
from .usage import UsageError
from ..chain.machine import MachineFileError
from .script import ScriptError, TranscriptEntry, load_script, run_script
from ..frontends.transports.base import Transport

log = logging.getLogger("coolmuscle")

EXIT_FAILED = 1
EXIT_USAGE = 2
EXIT_INTERNAL = 70

app = typer.Typer(name="coolmuscle", add_completion=False, no_args_is_help=True,
                  pretty_exceptions_enable=False,
                  help="A virtual Cool Muscle integrated servo motor and host tools.")

err = Console(stderr=True, soft_wrap=True, highlight=False)


class Firmware(str, enum.Enum):
    cm2 = "cm2"
    rt3 = "rt3"
    cm1 = "cm1"


def _default_chain_factory(*args: Any, **kwargs: Any) -> Any:
    from ..chain.daisy import Chain
    return Chain(*args, **kwargs)


#: Builds the chain for ``sim`` and ``run`` (same signature as ``Chain``); replaceable in tests.
chain_factory: Callable[..., Any] = _default_chain_factory


def default_state_dir() -> Path:
    """``$XDG_DATA_HOME/coolmuscle/state`` (``~/.local/share/coolmuscle/state``)."""
    base = os.environ.get("XDG_DATA_HOME") or os.path.expanduser("~/.local/share")
    return Path(base) / "coolmuscle" / "state"


def _show_path(path: Path) -> str:
    home = os.path.expanduser("~")
    text = str(path)
    if home not in ("", "/") and text.startswith(home + os.sep):
        return "~" + text[len(home):]
    return text


def _make_chain(motors: int, firmware: Firmware, state: Path | None, pace: bool,
                machine: Path | None = None, per_motor: str | None = None) -> Any:
    if state is not None:
        try:
            state.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise TransportError(f"cannot use state directory {state}: "
                                 f"{exc.strerror or exc}") from exc
    extra: dict[str, Any] = {}
    if machine is not None:
        from ..chain.machine import load_machine
        extra["machine"] = load_machine(machine)
    return chain_factory(None, motors, firmware=per_motor or firmware.value, state_dir=state,
                         pacing=pace, **extra)


_MACHINE_HELP = "Machine file (TOML): load, stoppers, sensors, faults (docs/machine-file.md)."


def _ids(motors: int) -> str:
    return "ID1" if motors == 1 else f"ID1-ID{motors}"


def _setup_logging(verbose: bool) -> None:
    logging.basicConfig(level=logging.INFO if verbose else logging.WARNING, stream=sys.stderr,
                        format="coolmuscle: %(message)s")


# -- sim -----------------------------------------------------------------
def _transports(tcp: str | None, pty: bool, pty_link: Path | None, stdio: bool,
                modbus: tuple[str | None, str | None, str | None] = (None, None, None),
                enip: bool = False) -> list[Transport]:
    from ..frontends import transports
    from ..frontends.transports.tcp import DEFAULT_PORT, parse_address

    chosen: list[Transport] = []
    modbus_rtu, modbus_tcp, com1 = modbus
    if tcp is None and not (pty or pty_link or stdio or modbus_rtu or modbus_tcp or enip):
        tcp = str(DEFAULT_PORT)
    if tcp is not None:
        try:
            host, port = parse_address(tcp)
        except TransportError as exc:
            raise UsageError(f"--tcp: {exc}") from None
        chosen.append(transports.create("tcp", host=host, port=port))
    if pty or pty_link is not None:
        chosen.append(transports.create("pty", link=pty_link))
    if stdio:
        chosen.append(transports.create("stdio"))
    chosen += _modbus_transports(modbus_rtu, modbus_tcp, com1)
    return chosen


def _ethercat_transports(iface: str, bridge: str, motors: int, tcp: str | None, pty: bool,
                         pty_link: Path | None, stdio: bool,
                         modbus: tuple[str | None, str | None, str | None],
                         ) -> tuple[list[Transport], int, str]:
    """``--ethercat IFACE --bridge B``: the slave plus any line transport asked for."""
    from ..frontends.ethercat.cli import EthercatUsageError, chain_firmware, sim_transport
    if motors not in (1, 4):
        raise UsageError("--ethercat serves the bridge's four motors ID1-ID4 (manual 1.4)")
    try:
        fw = chain_firmware(bridge)
    except EthercatUsageError as exc:
        raise UsageError(f"--bridge: {exc}") from None
    chosen: list[Transport] = [sim_transport(iface, bridge)]  # type: ignore[list-item]
    if tcp or pty or pty_link or stdio or any(modbus):
        chosen += _transports(tcp, pty, pty_link, stdio, modbus)
    return chosen, 4, fw


def _modbus_transports(rtu: str | None, tcp: str | None, com1: str | None) -> list[Transport]:
    """``--modbus-rtu``, ``--modbus-tcp``, ``--com1`` (docs/modbus.md)."""
    from ..frontends import transports
    from ..frontends.transports.tcp import parse_address

    chosen: list[Transport] = []
    if rtu is not None:
        chosen.append(transports.create("modbus-rtu", where=rtu))
    if tcp is not None:
        try:
            host, port = parse_address(tcp)
        except TransportError as exc:
            raise UsageError(f"--modbus-tcp: {exc}") from None
        chosen.append(transports.create("modbus-tcp", host=host, port=port))
    if com1 is not None:
        chosen.append(transports.create("com1", where=com1))
    return chosen


def _enip_transports(value: str | None, io_port: int, firmware: Firmware,
                     priority: int | None = None) -> list[Transport]:
    """``--enip`` (docs/enip.md)."""
    if value is None:
        return []
    from ..frontends.enip.cli import transports as enip_transports
    try:
        return enip_transports(value, io_port, firmware.value, priority)
    except TransportError as exc:
        raise UsageError(str(exc)) from None


async def _serve(chain: Any, chosen: list[Transport], motors: int, firmware: Firmware,
                 state: Path | None, scale: float, label: str | None = None) -> None:
    from ..frontends.transports.service import Service

    service = Service(chain, chosen, scale=scale)
    await service.start()
    err.print(f"coolmuscle: virtual {label or firmware.value.upper()} {_ids(motors)} ready",
              markup=False)
    where = "   ".join(t.describe() for t in chosen)
    shown = _show_path(state) if state is not None else "none, not saved"
    err.print(f"{where}   (state: {shown})", markup=False)
    station = _modbus_station(chain)
    if station:
        err.print(f"COM0 speaks Modbus RTU, station {station} (K81.1={station}); for the text "
                  "line send FFFFFFFFF, then K81.1=0 (5.6.9)", markup=False)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    try:
        await service.wait(stop)
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)
        await service.close()


def _modbus_station(chain: Any) -> int:
    line = getattr(chain, "modbus_line", None)
    return line.station() if line is not None and line.active() else 0


@app.command()
def sim(
    tcp: Optional[str] = typer.Option(None, "--tcp", metavar="[HOST:]PORT",
                                      help="Serve TCP (default when no transport is chosen: "
                                           "127.0.0.1:5150; port 0 picks a free one)."),
    pty: bool = typer.Option(False, "--pty", help="Serve a pseudo-terminal serial port."),
    pty_link: Optional[Path] = typer.Option(None, "--pty-link", metavar="PATH",
                                            help="Stable symlink to the pty (implies --pty)."),
    stdio: bool = typer.Option(False, "--stdio",
                               help="Serve stdin/stdout (ends at end of input)."),
    modbus_rtu: Optional[str] = typer.Option(
        None, "--modbus-rtu", metavar="pty|DEVICE",
        help="COM0 as a Modbus RTU slave on a new pty or a serial device (sets K81.1=1 "
             "when it is 0)."),
    modbus_tcp: Optional[str] = typer.Option(
        None, "--modbus-tcp", metavar="[HOST:]PORT",
        help="Serve the Modbus map over Modbus TCP (e.g. 1502; host 127.0.0.1)."),
    com1: Optional[str] = typer.Option(
        None, "--com1", metavar="pty|DEVICE",
        help="COM1 of the final motor (Modbus host when its K84=1) on a new pty or a "
             "serial device."),
    state: Optional[Path] = typer.Option(
        None, "--state", metavar="DIR",
        help="State directory (default: ~/.local/share/coolmuscle/state)."),
    no_state: bool = typer.Option(False, "--no-state", help="Do not load or save any state."),
    motors: int = typer.Option(1, "--motors", min=1, max=15, help="Motors on the chain."),
    firmware: Firmware = typer.Option(Firmware.cm2, "--firmware", help="Firmware profile."),
    pace: bool = typer.Option(False, "--pace",
                              help="Bytes take their wire time at the K20 baud rate."),
    time_scale: float = typer.Option(1.0, "--time-scale", metavar="X",
                                     help="Virtual seconds per wall second."),
    verbose: bool = typer.Option(False, "--verbose", "-v", help="Log connections."),
    machine: Optional[Path] = typer.Option(None, "--machine", metavar="AXIS.toml",
                                           help=_MACHINE_HELP),
    ethercat: Optional[str] = typer.Option(
        None, "--ethercat", metavar="IFACE",
        help="Serve the EtherCAT Cool Muscle Bridge as a slave on raw interface IFACE "
             "(4 motors; root or CAP_NET_RAW; docs/ethercat.md)."),
    bridge: str = typer.Option("EB02", "--bridge", metavar="EB01|EB02|EB12",
                               help="Bridge variant for --ethercat (firmware of ID1-ID4)."),
    enip: Optional[str] = typer.Option(
        None, "--enip", metavar="[HOST[:PORT]]",
        help="CM1 EtherNet/IP module: TCP/UDP 44818 and Class 1 I/O (default "
             "127.0.0.1; needs --firmware cm1; docs/enip.md)."),
    enip_io_port: int = typer.Option(2222, "--enip-io-port", metavar="PORT", min=0,
                                     max=65535, help="UDP port of Class 1 I/O."),
    enip_priority: Optional[int] = typer.Option(
        None, "--enip-rt-priority", metavar="N", min=1, max=99,
        help="Send Class 1 packets from a SCHED_FIFO thread of priority N (needs root)."),
) -> None:
    """Serve a virtual chain in real time until Ctrl-C or SIGTERM."""
    _setup_logging(verbose)
    if state is not None and no_state:
        raise UsageError("--state and --no-state exclude each other")
    if not time_scale > 0:
        raise UsageError("--time-scale must be > 0")
    state_dir = None if no_state else (state or default_state_dir()).expanduser()
    if (modbus_rtu or modbus_tcp) and firmware == Firmware.cm1:
        raise UsageError("cm1 has no Modbus (its K78-K85 are other parameters)")
    fw = ""
    if ethercat is not None:          # the bridge decides the firmware (--firmware unused)
        if enip is not None:
            raise UsageError("--ethercat and --enip exclude each other (the bridge's four "
                             "motors are not the EtherNet/IP module's CM1)")
        chosen, motors, fw = _ethercat_transports(ethercat, bridge, motors, tcp, pty, pty_link,
                                                  stdio, (modbus_rtu, modbus_tcp, com1))
        chain = _make_chain(motors, firmware, state_dir, pace, machine, fw)
    else:
        chosen = _transports(tcp, pty, pty_link, stdio, (modbus_rtu, modbus_tcp, com1),
                             enip=enip is not None)
        chosen += _enip_transports(enip, enip_io_port, firmware, enip_priority)
        chain = _make_chain(motors, firmware, state_dir, pace, machine)
    try:
        label = fw.upper().replace(",", "/") if ethercat is not None else None
        asyncio.run(_serve(chain, chosen, motors, firmware, state_dir, time_scale, label))
    finally:
        chain.close()
    err.print("coolmuscle: stopped", markup=False)


# -- run -----------------------------------------------------------------
@app.command()
def run(
    file: Path = typer.Argument(..., metavar="FILE.cml", help="Script / golden transcript."),
    until: Optional[float] = typer.Option(None, "--until", metavar="SECONDS",
                                          help="After the script, run on to this virtual time."),
    trace: Optional[Path] = typer.Option(
        None, "--trace", metavar="OUT.csv",
        help="Write a trace: CSV, or Parquet for OUT.parquet (needs pyarrow)."),
    plot: Optional[Path] = typer.Option(None, "--plot", metavar="OUT.png", help="Plot the trace."),
    xy: Optional[str] = typer.Option(
        None, "--xy", metavar="X,Y",
        help="With --plot: draw the XY path of motors X and Y (default: pairs that "
             "interpolated; 'none' for no XY panel)."),
    motors: int = typer.Option(1, "--motors", min=1, max=15, help="Motors on the chain."),
    firmware: Firmware = typer.Option(Firmware.cm2, "--firmware", help="Firmware profile."),
    state: Optional[Path] = typer.Option(
        None, "--state", metavar="DIR",
        help="Start from (and save to) this state (default: a fresh chain)."),
    check: bool = typer.Option(False, "--check",
                               help="Print only the verdict; fail without expectations."),
    pace: bool = typer.Option(False, "--pace",
                              help="Bytes take their wire time at the K20 baud rate."),
    record: Optional[Path] = typer.Option(
        None, "--record", metavar="OUT.cml",
        help="Write the script with the received bytes as expectations."),
    machine: Optional[Path] = typer.Option(None, "--machine", metavar="AXIS.toml",
                                           help=_MACHINE_HELP),
) -> None:
    """Run a script in fast virtual time, print every line, check expectations."""
    _setup_logging(False)
    script = load_script(file)
    if check and not script.expectations:
        raise UsageError(f"{file}: --check needs a script with '<<' expectations")
    if until is not None and until < 0:
        raise UsageError("--until must be >= 0")
    xy_pairs = _xy_pairs(xy, motors)
    if trace is not None:
        from .trace import TraceFormatError, check_trace_path
        try:
            check_trace_path(trace)
        except TraceFormatError as exc:
            raise UsageError(str(exc)) from None
    chain = _make_chain(motors, firmware, state.expanduser() if state else None, pace,
                        machine)
    try:
        if plot is not None:
            from .trace import NoTraceRecorderError, record as record_trace
            try:
                record_trace(chain)
            except NoTraceRecorderError as exc:
                raise ScriptError(f"cannot plot to {plot}: {exc}") from None

        def show(entry: TranscriptEntry) -> None:
            sys.stdout.write(entry.format() + "\n")

        result = run_script(script, chain, until=until, trace=trace,
                            on_entry=None if check else show)
        sys.stdout.flush()
        if plot is not None:
            from .plot import plot as plot_chain
            if xy_pairs is None:
                plot_chain(chain, plot)
            else:
                plot_chain(chain, plot, xy=xy_pairs)
    finally:
        chain.close()
    if record is not None:
        try:
            record.write_text(result.to_script(), encoding="utf-8")
        except OSError as exc:
            raise ScriptError(f"cannot write {record}: {exc.strerror or exc}") from exc
    if not result.ok:
        err.print(f"coolmuscle: {result.summary()}", markup=False)
        raise typer.Exit(EXIT_FAILED)
    if check:
        sys.stdout.write(f"coolmuscle: {result.summary()}\n")
    elif script.expectations:
        err.print(f"coolmuscle: {result.summary()}", markup=False)


def _xy_pairs(text: str | None, motors: int) -> list[tuple[int, int]] | None:
    """``--xy 1,2`` -> [(1, 2)]; ``none`` -> []; absent -> None (automatic)."""
    if text is None:
        return None
    if text.strip().lower() == "none":
        return []
    parts = text.split(",")
    try:
        x, y = (int(p) for p in parts)
    except ValueError:
        raise UsageError(f"--xy takes two motor IDs as X,Y, not {text!r}") from None
    if not (1 <= x <= motors and 1 <= y <= motors) or x == y:
        raise UsageError(f"--xy {text}: two different IDs of the chain (1..{motors})")
    return [(x, y)]


def _register_tools() -> None:
    from ..frontends.enip.cli import register as register_enip
    from .commands import register
    register(app)
    register_enip(app)   # coolmuscle enip eds


_register_tools()  # check, upload, term (coolmuscle.tools)


@app.command()
def version() -> None:
    """Print the version."""
    sys.stdout.write(f"coolmuscle {__version__}\n")


def _register_subapps() -> None:
    from ..frontends.ethercat.cli import app as ethercat_app
    app.add_typer(ethercat_app)


_register_subapps()


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``coolmuscle`` command: one-line errors, meaningful exit codes."""
    from ..frontends.enip.cli import optional_value_argv
    try:
        app(args=optional_value_argv(argv), prog_name="coolmuscle")
    except SystemExit:
        raise
    except KeyboardInterrupt:
        err.print("coolmuscle: interrupted", markup=False)
        raise SystemExit(130) from None
    except BrokenPipeError:  # `coolmuscle run x.cml | head`: the reader left, not an error
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        raise SystemExit(EXIT_FAILED) from None
    except (UsageError, ScriptError, MachineFileError) as exc:
        _report(exc, EXIT_USAGE)
    except (CoolMuscleError, OSError) as exc:
        _report(exc, EXIT_FAILED)
    except Exception as exc:  # a bug: still one line unless asked for more
        _report(exc, EXIT_INTERNAL, prefix="internal error: ")


def _report(exc: BaseException, code: int, prefix: str = "") -> None:
    if os.environ.get("COOLMUSCLE_DEBUG"):
        traceback.print_exc()
    text = str(exc) or type(exc).__name__
    if prefix:
        text = f"{prefix}{type(exc).__name__}: {text} (COOLMUSCLE_DEBUG=1 shows a traceback)"
    err.print(f"coolmuscle: error: {text}", markup=False)
    raise SystemExit(code) from None

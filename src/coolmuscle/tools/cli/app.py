"""The ``coolmuscle`` command (typer + rich): ``sim`` and ``run``.

Owns command-line parsing, the ready banner, signal handling and the mapping of
errors to one-line messages and exit codes.  No traceback reaches the user
(set ``COOLMUSCLE_DEBUG=1`` to see one):

* 0 success; 1 a failed run (expectation mismatch, ``@until`` timeout, model error)
  or a runtime error (port in use, store); 2 bad usage or a bad script;
  70 an internal error (a bug: please report it).

``sim`` serves a virtual chain over TCP / a pty / RFC 2217 / stdio in real time until Ctrl-C or
SIGTERM (docs/transports.md); ``run`` plays a script in fast virtual time and checks
its expectations (docs/scripts.md); ``check``, ``upload``, ``term`` and ``capture`` are
the host tools of :mod:`coolmuscle.tools` (docs/user-guide.md).
"""

from __future__ import annotations

import asyncio
import enum
import logging
import math
import os
import signal
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import typer
from rich.console import Console

from ...device.api import ChainFactory, Device
from ...errors import TransportError
from ...frontends.transports.base import Transport
from ...needs import needs_posix, realtime_problem
from ..script.runner import Script, load_script
from .exits import EXIT_FAILED, EXIT_INTERNAL, EXIT_USAGE, guarded  # noqa: F401 (public)
from .run import header_defaults, make_chain, run_command, setup_logging
from .stopsignals import (
    STOP_SIGNALS,
    SignalStop,
    check_stop,
    clear_stop,
    ignore_stop_signals,
    install_startup_handlers,
    run_served,
    stop_line,
)
from .usage import UsageError
from .version import version_text

log = logging.getLogger("coolmuscle")


app = typer.Typer(name="coolmuscle", add_completion=False, no_args_is_help=True,
                  pretty_exceptions_enable=False,
                  help="A virtual Cool Muscle integrated servo motor and host tools.")

err = Console(stderr=True, soft_wrap=True, highlight=False)


def _flags_take_no_value() -> None:
    """The help shows no ``<bool>`` after a flag such as ``--pty`` (it takes no value);
    typer >= 0.17 prints every option's type, flags included."""
    from typer.core import TyperOption

    shown = TyperOption.display_type_rich

    def display_type_rich(self: TyperOption, ctx: Any) -> str | None:
        return None if self.is_flag and self.metavar is None else shown(self, ctx)

    TyperOption.display_type_rich = display_type_rich  # type: ignore[method-assign]


_flags_take_no_value()


class Firmware(str, enum.Enum):
    cm2 = "cm2"
    rt3 = "rt3"
    cm1 = "cm1"


def _default_chain_factory(*args: Any, **kwargs: Any) -> Device:
    from ...chain.daisy import Chain
    return Chain(*args, **kwargs)


#: Builds the chain for ``sim`` and ``run`` (same signature as ``Chain``); replaceable in tests.
chain_factory: ChainFactory = _default_chain_factory


def default_state_dir() -> Path:
    """``$XDG_DATA_HOME/coolmuscle/state`` (``~/.local/share/coolmuscle/state``; on
    Windows ``%LOCALAPPDATA%\\coolmuscle\\state``).

    A relative ``XDG_DATA_HOME`` is ignored, as the XDG base directory spec says
    ("If an implementation encounters a relative path ... it should consider the
    path invalid and ignore it")."""
    xdg = os.environ.get("XDG_DATA_HOME", "")
    local = os.environ.get("LOCALAPPDATA", "") if os.name == "nt" else ""
    base = (xdg if xdg and os.path.isabs(xdg) else local if local
            else os.path.expanduser("~/.local/share"))
    return Path(base) / "coolmuscle" / "state"


def _show_path(path: Path) -> str:
    home = os.path.expanduser("~")
    text = str(path)
    if home not in ("", "/") and text.startswith(home + os.sep):
        return "~" + text[len(home):]
    return text


def _make_chain(motors: int, firmware: Firmware, state: Path | None, pace: bool,
                machine: Path | None = None, per_motor: str | None = None) -> Device:
    return make_chain(chain_factory, motors, per_motor or firmware.value, state, pace, machine)


_WEB_HELP = ("Serve the web dashboard (docs/web.md) on [HOST:]PORT, default "
             "127.0.0.1:8080; another host than loopback needs the printed token.")


_MACHINE_HELP = "Machine file (TOML): load, stoppers, sensors, faults (docs/machine-file.md)."


def _ids(motors: int) -> str:
    return "ID1" if motors == 1 else f"ID1-ID{motors}"


def _setup_logging(verbose: bool) -> None:
    setup_logging(verbose)


# -- sim -----------------------------------------------------------------
def _transports(tcp: str | None, pty: bool, pty_link: Path | None, stdio: bool,
                modbus: tuple[str | None, str | None, str | None] = (None, None, None),
                enip: bool = False, rfc2217: str | None = None) -> list[Transport]:
    from ...frontends import transports
    from ...frontends.transports.tcp import DEFAULT_PORT, parse_address

    chosen: list[Transport] = []
    modbus_rtu, modbus_tcp, com1 = modbus
    if tcp is None and not (pty or pty_link or stdio or modbus_rtu or modbus_tcp or enip
                            or rfc2217 is not None):
        tcp = str(DEFAULT_PORT)
    for option, name, value in (("--tcp", "tcp", tcp), ("--rfc2217", "rfc2217", rfc2217)):
        if value is None:
            continue
        try:
            host, port = parse_address(value)
        except TransportError as exc:
            raise UsageError(f"{option}: {exc}") from None
        chosen.append(transports.create(name, host=host, port=port))
    if pty or pty_link is not None:
        needs_posix("--pty-link" if pty_link is not None and not pty else "--pty")
        chosen.append(transports.create("pty", link=pty_link))
    if stdio:
        needs_posix("--stdio", "--tcp")
        chosen.append(transports.create("stdio"))
    chosen += _modbus_transports(modbus_rtu, modbus_tcp, com1)
    return chosen


def _ethercat_transports(iface: str, bridge: str, motors: int, tcp: str | None, pty: bool,
                         pty_link: Path | None, stdio: bool,
                         modbus: tuple[str | None, str | None, str | None],
                         rfc2217: str | None = None) -> tuple[list[Transport], int, str]:
    """``--ethercat IFACE --bridge B``: the slave plus any line transport asked for."""
    from .ethercat import EthercatUsageError, chain_firmware, sim_transport
    if motors not in (1, 4):
        raise UsageError("--ethercat serves the bridge's four motors ID1-ID4 (manual 1.4)")
    try:
        fw = chain_firmware(bridge)
    except EthercatUsageError as exc:
        raise UsageError(f"--bridge: {exc}") from None
    chosen: list[Transport] = [sim_transport(iface, bridge)]
    problem = realtime_problem()
    if problem is not None:          # said once: the frame thread and the model's both
        err.print(f"coolmuscle: note: the bridge runs at normal priority ({problem}); "
                  "its answers and cycles may come late on a busy machine", markup=False)
    if tcp or pty or pty_link or stdio or any(modbus) or rfc2217 is not None:
        chosen += _transports(tcp, pty, pty_link, stdio, modbus, rfc2217=rfc2217)
    return chosen, 4, fw


def _modbus_transports(rtu: str | None, tcp: str | None, com1: str | None) -> list[Transport]:
    """``--modbus-rtu``, ``--modbus-tcp``, ``--com1`` (docs/modbus.md)."""
    from ...frontends import transports
    from ...frontends.transports.tcp import parse_address

    chosen: list[Transport] = []
    if rtu is not None:
        needs_posix("--modbus-rtu", "--modbus-tcp")
        chosen.append(transports.create("modbus-rtu", where=rtu))
    if tcp is not None:
        try:
            host, port = parse_address(tcp)
        except TransportError as exc:
            raise UsageError(f"--modbus-tcp: {exc}") from None
        chosen.append(transports.create("modbus-tcp", host=host, port=port))
    if com1 is not None:
        needs_posix("--com1", "--modbus-tcp for the Modbus side")
        chosen.append(transports.create("com1", where=com1))
    return chosen


def _enip_transports(value: str | None, io_port: int, firmware: Firmware,
                     priority: int | None = None) -> list[Transport]:
    """``--enip`` (docs/enip.md)."""
    if value is None:
        return []
    from .enip import transports as enip_transports
    try:
        return enip_transports(value, io_port, firmware.value, priority)
    except TransportError as exc:
        raise UsageError(str(exc)) from None


#: ``sim --time-scale``: virtual seconds per wall second, at most a million (beyond,
#: a wall second would be more virtual time than the motor's clock counts usefully).
MAX_TIME_SCALE = 1e6


async def _serve(chain: Device, chosen: list[Transport], motors: int, firmware: Firmware,
                 state: Path | None, scale: float, stop: asyncio.Event,
                 label: str | None = None) -> None:
    """Start the transports, print the banner, serve until ``stop`` (run by
    :func:`.stopsignals.run_served`: a stop signal sets it)."""
    from ...frontends.transports.service import Service

    service = Service(chain, chosen, scale=scale)
    try:          # a stop signal may land anywhere from here on: close what was started
        await service.start()
        check_stop()      # a signal during start-up (or swallowed before): one line, 130
        err.print(f"coolmuscle: virtual {label or firmware.value.upper()} {_ids(motors)} "
                  "ready", markup=False)
        where = "   ".join(t.describe() for t in chosen)
        shown = _show_path(state) if state is not None else "none, not saved"
        err.print(f"{where}   (state: {shown})", markup=False)
        station = chain.modbus_station()
        if station:
            asked = any(t.name == "modbus-rtu" for t in chosen)
            err.print(_modbus_notice(station, state, asked), markup=False)
        await service.wait(stop)      # from "ready" on, a signal is a served stop
    finally:
        ignore_stop_signals()          # a second signal must not cut the clean-up short
        await service.close()


def _modbus_notice(station: int, state: Path | None, asked: bool = False) -> str:
    """Why a plain ``sim`` answers no CML text: K81 (kept like every K) hands COM0 to
    Modbus RTU (5.6.1), and how to get the text line back (5.6.9, ``--reset``)."""
    saved = f" (saved in {_show_path(state)})" if state is not None else ""
    if asked and state is None:
        return (f"coolmuscle: note: K81.1={station}: COM0 speaks Modbus RTU; no state is "
                "saved, so the next sim starts with K81.1=0 (CML text).")
    if asked:
        return (f"coolmuscle: note: K81.1={station}{saved}: COM0 speaks Modbus RTU; the "
                "motor keeps K81, so later sims with this state speak Modbus on COM0 too, "
                "until you start one with --reset or send K81.1=0 in text mode (5.6.9).")
    return (f"coolmuscle: note: K81.1={station}{saved}: COM0 (the TCP port, the pty, "
            f"stdio) speaks Modbus RTU as station {station}, not CML text. For CML text "
            "again: start with --reset (forgets all saved data and K values), or send "
            "FFFFFFFFF and then K81.1=0 (5.6.9).")


def _reset_state(state: Path | None) -> None:
    """``sim --reset``: forget what the state directory holds (factory state).  A store
    file that cannot be read at all (damaged, not a store) is kept aside, not lost."""
    if state is None:
        return
    from ...errors import DamagedStoreError
    from ...motor.state.store import DEFAULT_FILENAME, Store, set_aside
    path = state / DEFAULT_FILENAME
    if not path.exists():
        return
    try:
        with Store(path, writer=True) as store:     # not under a running sim
            for motor_id in store.motors():
                store.delete(motor_id)
    except DamagedStoreError as exc:
        kept = set_aside(path)
        err.print(f"coolmuscle: state reset: {_show_path(path)} {exc.problem}: kept it as "
                  f"{_show_path(Path(kept))}; {_show_path(state)} holds factory settings",
                  markup=False)
        return
    err.print(f"coolmuscle: state reset: {_show_path(state)} holds factory settings",
              markup=False)


@app.command()
def sim(
    tcp: str | None = typer.Option(None, "--tcp", metavar="[HOST:]PORT",
                                      help="Serve TCP (default when no transport is chosen: "
                                           "127.0.0.1:5150; port 0 picks a free one)."),
    pty: bool = typer.Option(False, "--pty", help="Serve a pseudo-terminal serial port."),
    pty_link: Path | None = typer.Option(None, "--pty-link", metavar="PATH",
                                            help="Stable symlink to the pty (implies --pty)."),
    rfc2217: str | None = typer.Option(
        None, "--rfc2217", metavar="[HOST:]PORT",
        help="Serve an RFC 2217 serial port (rfc2217:// clients, virtual COM port tools; "
             "host 127.0.0.1)."),
    stdio: bool = typer.Option(False, "--stdio",
                               help="Serve stdin/stdout (ends at end of input)."),
    modbus_rtu: str | None = typer.Option(
        None, "--modbus-rtu", metavar="pty|DEVICE",
        help="COM0 as a Modbus RTU slave on a new pty or a serial device (sets K81.1=1 "
             "when it is 0)."),
    modbus_tcp: str | None = typer.Option(
        None, "--modbus-tcp", metavar="[HOST:]PORT",
        help="Serve the Modbus map over Modbus TCP (e.g. 1502; host 127.0.0.1)."),
    com1: str | None = typer.Option(
        None, "--com1", metavar="pty|DEVICE",
        help="COM1 of the final motor (Modbus host when its K84=1) on a new pty or a "
             "serial device."),
    state: Path | None = typer.Option(
        None, "--state", metavar="DIR",
        help="State directory (default: ~/.local/share/coolmuscle/state)."),
    no_state: bool = typer.Option(False, "--no-state", help="Do not load or save any state."),
    reset: bool = typer.Option(False, "--reset",
                               help="Forget the saved state first (factory settings, "
                                    "K81=0: CML text on COM0)."),
    motors: int = typer.Option(1, "--motors", min=1, max=15, help="Motors on the chain."),
    firmware: Firmware = typer.Option(Firmware.cm2, "--firmware", help="Firmware profile."),
    pace: bool = typer.Option(False, "--pace",
                              help="Bytes take their wire time at the K20 baud rate."),
    time_scale: float = typer.Option(1.0, "--time-scale", metavar="X",
                                     help="Virtual seconds per wall second."),
    verbose: bool = typer.Option(False, "--verbose", "-v", help="Log connections."),
    machine: Path | None = typer.Option(None, "--machine", metavar="AXIS.toml",
                                           help=_MACHINE_HELP),
    web: str | None = typer.Option(None, "--web", metavar="[[HOST:]PORT]",
                                      help=_WEB_HELP),
    ethercat: str | None = typer.Option(
        None, "--ethercat", metavar="IFACE",
        help="Serve the EtherCAT Cool Muscle Bridge as a slave on raw interface IFACE "
             "(4 motors; root or CAP_NET_RAW; docs/ethercat.md)."),
    bridge: str = typer.Option("EB02", "--bridge", metavar="EB01|EB02|EB12",
                               help="Bridge variant for --ethercat (firmware of ID1-ID4)."),
    enip: str | None = typer.Option(
        None, "--enip", metavar="[HOST[:PORT]]",
        help="CM1 EtherNet/IP module: TCP/UDP 44818 and Class 1 I/O (default "
             "127.0.0.1; needs --firmware cm1; docs/enip.md)."),
    enip_io_port: int = typer.Option(2222, "--enip-io-port", metavar="PORT", min=0,
                                     max=65535, help="UDP port of Class 1 I/O."),
    enip_priority: int | None = typer.Option(
        None, "--enip-rt-priority", metavar="N", min=1, max=99,
        help="Send Class 1 packets from a SCHED_FIFO thread of priority N (needs root)."),
) -> None:
    """Serve a virtual chain in real time until Ctrl-C, SIGTERM or SIGHUP."""
    _setup_logging(verbose)
    if state is not None and no_state:
        raise UsageError("--state and --no-state exclude each other")
    if not (math.isfinite(time_scale) and 0 < time_scale <= MAX_TIME_SCALE):
        raise UsageError(f"--time-scale must be above 0 and at most {MAX_TIME_SCALE:g}")
    state_dir = None if no_state else (state or default_state_dir()).expanduser()
    if (modbus_rtu or modbus_tcp) and firmware == Firmware.cm1:
        raise UsageError("cm1 has no Modbus (its K78-K85 are other parameters)")
    check_stop()
    dashboard = _web_transport(web) if web is not None else None   # docs/web.md
    fw = ""
    if ethercat is not None:          # the bridge decides the firmware (--firmware unused)
        if enip is not None:
            raise UsageError("--ethercat and --enip exclude each other (the bridge's four "
                             "motors are not the EtherNet/IP module's CM1)")
        chosen, motors, fw = _ethercat_transports(ethercat, bridge, motors, tcp, pty, pty_link,
                                                  stdio, (modbus_rtu, modbus_tcp, com1),
                                                  rfc2217)
        if reset:
            _reset_state(state_dir)
        chain = _make_chain(motors, firmware, state_dir, pace, machine, fw)
    else:
        chosen = _transports(tcp, pty, pty_link, stdio, (modbus_rtu, modbus_tcp, com1),
                             enip=enip is not None, rfc2217=rfc2217)
        chosen += _enip_transports(enip, enip_io_port, firmware, enip_priority)
        if reset:
            _reset_state(state_dir)
        chain = _make_chain(motors, firmware, state_dir, pace, machine)
    if dashboard is not None:
        chosen.append(dashboard)
    try:
        check_stop()
        label = fw.upper().replace(",", "/") if ethercat is not None else None
        run_served(lambda stop: _serve(chain, chosen, motors, firmware, state_dir, time_scale,
                                       stop, label))
    finally:
        ignore_stop_signals()
        chain.close()
    err.print("coolmuscle: stopped", markup=False)



# -- run -----------------------------------------------------------------
@app.command()
def run(
    file: Path = typer.Argument(..., metavar="FILE.cml", help="Script / golden transcript."),
    until: float | None = typer.Option(None, "--until", metavar="SECONDS",
                                          help="After the script, run on to this virtual time."),
    trace: Path | None = typer.Option(
        None, "--trace", metavar="OUT.csv",
        help="Write a trace: CSV, or Parquet for OUT.parquet (needs pyarrow); streamed "
             "as the run goes."),
    trace_step: float = typer.Option(
        0.001, "--trace-step", metavar="SECONDS",
        help="Trace grid step (default 0.001); changes are recorded at their instant."),
    plot: Path | None = typer.Option(None, "--plot", metavar="OUT.png", help="Plot the trace."),
    xy: str | None = typer.Option(
        None, "--xy", metavar="X,Y",
        help="With --plot: draw the XY path of motors X and Y (default: pairs that "
             "interpolated; 'none' for no XY panel)."),
    motors: int | None = typer.Option(
        None, "--motors", min=1, max=15,
        help="Motors on the chain (default: the script's '# coolmuscle: motors=N', else 1)."),
    firmware: Firmware | None = typer.Option(
        None, "--firmware",
        help="Firmware profile (default: the script's 'firmware=', else cm2)."),
    state: Path | None = typer.Option(
        None, "--state", metavar="DIR",
        help="Start from (and save to) this state (default: a fresh chain)."),
    check: bool = typer.Option(False, "--check",
                               help="Print only the verdict; fail without expectations."),
    pace: bool = typer.Option(False, "--pace",
                              help="Bytes take their wire time at the K20 baud rate."),
    record: Path | None = typer.Option(
        None, "--record", metavar="OUT.cml",
        help="Write the script with the received bytes as expectations."),
    machine: Path | None = typer.Option(None, "--machine", metavar="AXIS.toml",
                                           help=_MACHINE_HELP),
    web: str | None = typer.Option(
        None, "--web", metavar="[[HOST:]PORT]",
        help="Play the script in real time and show it on the web dashboard "
             "(docs/web.md); starts when a page connects."),
    junit: Path | None = typer.Option(
        None, "--junit", metavar="FILE.xml",
        help="Also write the verdict as JUnit XML (the failing line of the script)."),
) -> None:
    """Run a script in fast virtual time, print every line, check expectations."""
    if web is not None:
        _setup_logging(False)
        script = load_script(file)
        motors, fw, machine = header_defaults(file, motors, firmware.value if firmware else None,
                                              machine)
        _run_web(script, web, until, (check, record, trace, plot, junit),
                 lambda: _make_chain(motors, Firmware(fw), state.expanduser() if state else None,
                                     pace, machine))
        return
    code = run_command(file, until=until, trace=trace, trace_step=trace_step, plot=plot, xy=xy,
                       motors=motors, firmware=firmware.value if firmware else None,
                       state=state, check=check, pace=pace, record=record, machine=machine,
                       chain_factory=chain_factory, junit=junit)
    if code:
        raise typer.Exit(code)


def _web_transport(address: str) -> Transport:
    """``--web [HOST:]PORT`` (coolmuscle.tools.web)."""
    from ..web.run import web_transport
    try:
        return web_transport(address)
    except TransportError as exc:
        raise UsageError(f"--web: {exc}") from None


def _run_web(script: Script, address: str, until: float | None, others: tuple[object, ...],
             make_chain: Callable[[], Device]) -> None:
    """``run FILE --web``: the script in real time on the dashboard (docs/web.md)."""
    from ..web.run import run_script_web
    from .run import check_run_times
    check_run_times(until)
    if any(o not in (None, False) for o in others):
        raise UsageError("--web shows the run live: --check, --record, --trace, --plot "
                         "and --junit are for fast runs (the page downloads the trace "
                         "and the plot)")
    _web_transport(address)                       # a bad address is a usage error
    chain = make_chain()
    try:
        run_script_web(script, chain, address, until=until,
                       err=lambda text: err.print(text, markup=False))
    finally:
        chain.close()


def _register_tools() -> None:
    from .enip import register as register_enip
    from .host_commands import register
    register(app)
    register_enip(app)   # coolmuscle enip eds


_register_tools()  # check, upload, term (coolmuscle.tools)


def _register_batch() -> None:
    from ..batch.commands import register
    register(app)


_register_batch()  # batch, sweep (coolmuscle.tools.batch.commands, docs/batch.md)


def _register_twin() -> None:
    from ..twin.commands import register
    register(app)


_register_twin()  # compare, fit (coolmuscle.tools.twin.commands, docs/twin.md)


def _register_capture() -> None:
    from ..capture.command import register
    register(app)


_register_capture()  # capture (coolmuscle.tools.capture, docs/user-guide.md)


def _register_desk() -> None:
    from ..desk.commands import register
    register(app)


_register_desk()  # scan, backup, restore, params diff (coolmuscle.tools.desk, docs/real-motor.md)


def _register_web() -> None:
    from ..web.command import register
    register(app)


_register_web()  # web: the page of a real motor (coolmuscle.tools.web, docs/real-motor.md)


@app.command()
def version() -> None:
    """Print the version, and whether the hot modules run compiled or as sources."""
    sys.stdout.write(version_text())


def _print_version(value: bool) -> None:
    if value:
        sys.stdout.write(version_text())
        raise typer.Exit()


@app.callback()
def _main_options(
    show_version: bool = typer.Option(False, "--version", callback=_print_version,
                                      is_eager=True, help="Print the version and exit."),
) -> None:
    """A virtual Cool Muscle integrated servo motor and host tools."""


def _register_subapps() -> None:
    from .ethercat import app as ethercat_app
    app.add_typer(ethercat_app)


_register_subapps()


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``coolmuscle`` command: one-line errors, meaningful exit codes.

    Called with ``argv`` (in-process, tests), the caller's signal handlers are put back
    on return."""
    saved = ({sig: signal.getsignal(sig) for sig in STOP_SIGNALS}
             if argv is not None and threading.current_thread() is threading.main_thread()
             else None)
    if argv is not None:
        clear_stop()                      # in-process: a new command
    try:
        _main(argv)
        check_stop()
    except SignalStop as exc:             # requested, its exception swallowed on the way
        ignore_stop_signals()
        text, code = stop_line(exc)
        err.print(text, markup=False)
        raise SystemExit(code) from None
    finally:
        for sig, handler in (saved or {}).items():
            signal.signal(sig, handler)


#: The commands that handle Ctrl-C as KeyboardInterrupt themselves: the terminal (at
#: its prompt a key), batch and sweep (they report what finished).  Every other command
#: stops with one line and 130 (typer turns a KeyboardInterrupt into a silent 130).
_OWN_CTRL_C = ("term", "batch", "sweep")


def _main(argv: list[str] | None) -> None:
    if threading.current_thread() is threading.main_thread():
        install_startup_handlers()    # also when started as coolmuscle.tools.cli.app:main
        args = sys.argv[1:] if argv is None else argv
        if next((a for a in args if not a.startswith("-")), "") in _OWN_CTRL_C:
            signal.signal(signal.SIGINT, signal.default_int_handler)
    from ..web.access import expand_web_flag  # a bare --web: 127.0.0.1:8080
    from ..web.command import expand_twin_flag  # a bare --twin: the default load
    from .enip import optional_value_argv

    def call() -> None:
        args = expand_twin_flag(expand_web_flag(sys.argv[1:] if argv is None else argv))
        app(args=optional_value_argv(args), prog_name="coolmuscle")
    guarded(call)

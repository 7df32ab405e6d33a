"""``coolmuscle capture``: relay a host program to a motor and write the session.

Registered on the ``coolmuscle`` command by :func:`register`.  Exit status: 0 the
capture ended with the host program (``--once``); 1 the link to the motor broke; 2 bad
usage (no such port, a missing directory, bad options: nothing written); 130 Ctrl-C
(128 + N for another stop signal) within a second, the file complete with its
``# end:`` line.
Messages are one line (docs/user-guide.md "coolmuscle capture").
"""

from __future__ import annotations

import os
import signal
import sys
from dataclasses import replace
from enum import Enum
from pathlib import Path
from typing import Annotated

import typer

from ...device.hostline import BAUD_RATES
from ...errors import TransportError
from ..cli.host_commands import FirmwareChoice
from ..cli.ports import port_url
from ..cli.run import stderr_line
from ..cli.stopsignals import SignalStop, ignore_stop_signals
from ..cli.usage import UsageError
from .ends import MotorPort, PtyHostSide, TcpHostSide
from .recording import CaptureFile, header_lines
from .relay import Relay
from .settings import LineSettings, probe

__all__ = ["capture", "register"]

#: Thread switch interval while relaying (s): a thread woken by a byte gets the
#: interpreter within this, not Python's default 5 ms (docs/performance.md).
SWITCH_INTERVAL = 0.0002
#: Seconds the host program gets to take what it has not read yet when the capture
#: ends by itself, and when it is stopped (Ctrl-C: the whole stop within a second).
END_FLUSH = 1.0
STOP_FLUSH = 0.2


class Parity(str, Enum):
    none = "none"
    even = "even"
    odd = "odd"


class OnOff(str, Enum):
    on = "on"
    off = "off"


def _say(text: str) -> None:
    stderr_line(f"coolmuscle: {text}")


def _check_out(out: Path) -> None:
    """The capture file can be made (checked before anything is opened)."""
    if out.is_dir():
        raise UsageError(f"--out {out}: a directory, not a file")
    parent = out.parent
    if not parent.is_dir():
        raise UsageError(f"--out {out}: no such directory {parent}")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise UsageError(f"--out {out}: cannot write in {parent}")


def _machine_word(machine: Path, out: Path) -> str:
    """The machine file as the header names it: relative to the capture's directory."""
    from ...chain.machine import load_machine
    if not machine.is_file():
        raise UsageError(f"--machine {machine}: no such file")
    load_machine(machine)                       # a bad file is refused now (exit 2)
    word = os.path.relpath(machine.resolve(), out.resolve().parent)
    if any(char.isspace() for char in word):
        raise UsageError(f"--machine {machine}: the header names the file as {word!r}, and "
                         "'run' reads a header path up to the first space: use a path "
                         "without spaces")
    return word


def _open_host(listen: str | None, pty: Path | None) -> TcpHostSide | PtyHostSide:
    if listen is not None:
        return TcpHostSide(listen)
    assert pty is not None
    return PtyHostSide(pty)


def _settings(motor: MotorPort, url: str, given: LineSettings, *, probing: bool,
              scan: bool, echo: OnOff | None, firmware: FirmwareChoice | None) -> LineSettings:
    """The header's settings: found by the probe, then what was given wins."""
    found = probe(motor.port, url, given, scan=scan, say=_say) if probing else given
    settings = found
    if echo is not None:
        wanted = echo is OnOff.on
        if found.echo is not None and found.echo != wanted:
            _say(f"note: --echo {echo.value} overrides what the motor said "
                 f"(K23={found.k23}: echo {found.echo_word()})")
        settings = replace(settings, echo=wanted)
    if firmware is not None:
        settings = replace(settings, firmware=firmware.value)
    return settings


def capture(
    url: Annotated[str, typer.Argument(
        metavar="PORT", help="The motor: a serial device, HOST:PORT (127.0.0.1:5150) or a "
                             "pyserial URL (socket://, rfc2217://, coolmuscle://).")],
    out: Annotated[Path, typer.Option(
        "--out", metavar="SESSION.cml", help="The capture file (written as it goes).")],
    listen: Annotated[str | None, typer.Option(
        "--listen", metavar="[HOST:]PORT",
        help="The host program connects here over TCP (socket://; host 127.0.0.1 unless "
             "given; port 0 picks a free one).")] = None,
    pty: Annotated[Path | None, typer.Option(
        "--pty", metavar="LINK",
        help="The host program opens a pseudo-terminal at LINK (a symlink, removed on "
             "exit).")] = None,
    baud: Annotated[int | None, typer.Option(
        "--baud", metavar="BPS",
        help="Baud rate of the motor's port (K20: 9600 ... 230400; default: found, else "
             "38400).")] = None,
    parity: Annotated[Parity | None, typer.Option(
        "--parity", help="Parity (K82; default: found, else none).")] = None,
    echo: Annotated[OnOff | None, typer.Option(
        "--echo", help="The motor echoes (K23 without 8); default: asked.")] = None,
    probing: Annotated[bool, typer.Option(
        "--probe/--no-probe", help="Ask the motor (?85, K20, K23) before the host program "
                                   "connects; not recorded.")] = True,
    motors: Annotated[int | None, typer.Option(
        "--motors", min=1, max=15, help="Motors on the chain (for the header).")] = None,
    firmware: Annotated[FirmwareChoice | None, typer.Option(
        "--firmware", help="Firmware profile (for the header; default: from ?85).")] = None,
    machine: Annotated[Path | None, typer.Option(
        "--machine", metavar="M.toml",
        help="The machine file that describes this machine (named in the header).")] = None,
    once: Annotated[bool, typer.Option(
        "--once", help="End when the host program disconnects (--listen).")] = False,
) -> None:
    """Relay a host program to a motor and record the session as a replayable script."""
    if (listen is None) == (pty is None):
        raise UsageError("give one of --listen [HOST:]PORT and --pty LINK (where the host "
                         "program connects)")
    if once and listen is None:
        raise UsageError("--once ends the capture when a TCP host disconnects: use it with "
                         "--listen")
    if baud is not None and baud not in BAUD_RATES.values():
        raise UsageError(f"--baud {baud}: the motor's rates are "
                         + ", ".join(str(b) for b in sorted(BAUD_RATES.values())) + " (K20)")
    _check_out(out)
    machine_word = _machine_word(machine, out) if machine is not None else None
    if pty is not None:
        from ...needs import needs_posix
        needs_posix("--pty", "--listen [HOST:]PORT and a virtual COM port tool")
        from ...frontends.transports.pty import SymLink
        try:
            SymLink(pty.expanduser()).check()
        except TransportError as exc:
            raise UsageError(f"--pty: {exc}") from None
    if listen is not None:
        from ...frontends.transports.tcp import parse_address
        try:
            parse_address(listen)
        except TransportError as exc:
            raise UsageError(f"--listen: {exc}") from None
    url = port_url(url)
    given = LineSettings(baud=baud or 38400, parity=(parity or Parity.none).value)
    try:
        motor = MotorPort(url, given.baud, given.parity)
    except TransportError as exc:
        raise UsageError(str(exc)) from None
    host: TcpHostSide | PtyHostSide | None = None
    relay: Relay | None = None
    record: CaptureFile | None = None
    stopped = "error"                     # what the end line says if setting up fails
    signum: int | None = None
    switch_interval = sys.getswitchinterval()
    try:
        settings = _settings(motor, url, given, probing=probing,
                             scan=baud is None and parity is None, echo=echo,
                             firmware=firmware)
        host = _open_host(listen, pty)
        try:
            record = CaptureFile(out, lambda started: header_lines(
                url, settings, started, motors=motors, machine=machine_word),
                on_error=lambda text: _say(f"warning: {text}; the relay goes on"))
        except OSError as exc:
            raise UsageError(f"--out {out}: {exc.strerror or exc}") from None
        relay = Relay(motor, host, record.put, once=once, say=_say)
        sys.setswitchinterval(SWITCH_INTERVAL)
        relay.start()
        _say(f"capture ready: host program on {host.describe()}; motor {url} "
             f"({settings.baud} bit/s, parity {settings.parity}, echo "
             f"{settings.echo_word()}); writing {out}; Ctrl-C ends it")
        stopped = relay.wait()
    except (KeyboardInterrupt, SignalStop) as exc:
        signum = exc.signum if isinstance(exc, SignalStop) else signal.SIGINT
        stopped = "ctrl-c" if signum == signal.SIGINT else signal.Signals(signum).name.lower()
    finally:
        ignore_stop_signals()                 # a second signal must not cut the file short
        sys.setswitchinterval(switch_interval)
        if record is not None:
            record.stop_waiting()             # the relay's threads end without waiting
        if relay is not None:                 # both ends too; Ctrl-C: at once
            relay.close(flush=STOP_FLUSH if signum is not None else END_FLUSH)
        else:
            if host is not None:
                host.close()
            motor.close()
        if record is not None:
            record.close(stopped)
    if signum is not None:
        raise SignalStop(signum)              # one line, exit 128 + N (130: Ctrl-C)
    assert relay is not None and record is not None
    if relay.error is not None:
        raise TransportError(relay.error)
    w = record.writer
    unsent = (f"; {relay.dropped} byte(s) from the motor came while no program took them "
              "(recorded, not passed on)" if relay.dropped else "")
    _say(f"capture ended ({stopped}): {w.sent_lines} line(s) sent, {w.received_lines} "
         f"received, in {out}{unsent}")


def register(app: typer.Typer) -> None:
    """Add ``capture`` to the ``coolmuscle`` command."""
    app.command()(capture)

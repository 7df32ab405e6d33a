"""``coolmuscle web PORT_OR_URL [--twin [MACHINE.toml]]``: the page in front of a real motor.

Opens PORT (a serial device, ``HOST:PORT`` or any pyserial URL, docs/real-motor.md
"Reaching the motor"), scans it as ``coolmuscle scan`` does, and serves the dashboard
of :mod:`.linepage` on ``--listen [HOST:]PORT`` (127.0.0.1:8080) until Ctrl-C, SIGTERM or
SIGHUP.  With ``--twin`` a virtual motor shadows the real one (:mod:`.twin`).

Bad input is one line and exit status 2, nothing served: no motor on PORT, a wrong
``--baud``, a port that cannot be opened, a machine file that does not load, an address
the page cannot listen on.
"""

from __future__ import annotations

import asyncio
import os
from collections.abc import Callable
from pathlib import Path

import typer

from ..cli.usage import UsageError

__all__ = ["register", "web", "expand_twin_flag"]

_PORT = ("The motor: a serial device (/dev/ttyUSB0, COM3), HOST:PORT (socket://HOST:PORT) "
         "or a pyserial URL (rfc2217://, coolmuscle://).")
_BAUD = ("A K20 rate to try (9600 ... 230400; repeat to try several; default: every "
         "K20 rate, 38400 first).")
#: ``--twin`` with no machine file (``expand_twin_flag``): the default load.
NO_MACHINE = "-"


def expand_twin_flag(argv: list[str]) -> list[str]:
    """Give a bare ``--twin`` its value: the word after it is a machine file when it ends
    in ``.toml`` or names a file, else ``--twin`` stands alone (the default load)."""
    out: list[str] = []
    for i, word in enumerate(argv):
        out.append(word)
        if word == "--twin":
            following = argv[i + 1] if i + 1 < len(argv) else None
            if following is None or not (following.lower().endswith(".toml")
                                         or (os.path.isfile(following)
                                             and not following.startswith("-"))):
                out.append(NO_MACHINE)
    return out


def _say(text: str) -> None:
    from ..cli.run import stderr_line
    stderr_line(text)


def web(
    port: str = typer.Argument(..., metavar="PORT_OR_URL", help=_PORT),
    listen: str = typer.Option("127.0.0.1:8080", "--listen", metavar="[HOST:]PORT",
                               help="Where the page is served (port 0 picks a free one; "
                                    "another host than loopback needs the printed token)."),
    baud: list[int] | None = typer.Option(None, "--baud", metavar="BPS", help=_BAUD),
    ids: str | None = typer.Option(None, "--ids", metavar="IDS",
                                   help="Motor IDs to ask, e.g. 1-3 (default: ID1, ID2 ... "
                                        "up to the first that is silent)."),
    twin: str | None = typer.Option(
        None, "--twin", metavar="[MACHINE.toml]",
        help="A virtual motor beside the real one, sent every line (its load from "
             "MACHINE.toml, docs/machine-file.md); the charts overlay both and the page "
             "shows each difference beyond the compare tolerances."),
    poll: bool = typer.Option(True, "--poll/--no-poll",
                              help="Poll position, speed, torque, temperature and status."),
) -> None:
    """Serve the web dashboard in front of a real motor (or any line that speaks CML).

    A poll the line can carry; console, banks, K editor, buttons, desk (docs/real-motor.md).
    """
    from ...chain.machine import load_machine
    from ...errors import CoolMuscleError
    from ..desk.actions import parse_bauds, parse_ids
    machine = None if twin in (None, NO_MACHINE) else Path(str(twin))
    try:
        bauds, chosen = parse_bauds(baud), parse_ids(ids)
        if machine is not None:
            load_machine(machine)                # a bad file: said before the line opens
        serve(port, listen, bauds, chosen, twin is not None, machine, poll, _say)
    except CoolMuscleError as exc:               # no motor, a wrong rate, a bad file ...
        raise UsageError(str(exc)) from None


def serve(port: str, listen: str, bauds: tuple[int, ...] | None,
          ids: tuple[int, ...] | None, with_twin: bool, machine: Path | None, poll: bool,
          say: Callable[[str], None]) -> None:
    """Open the line and serve its page until a stop signal (see the module docstring)."""
    from ..cli.stopsignals import ignore_stop_signals, run_served
    from .access import parse_web_address

    host, web_port = parse_web_address(listen)

    async def main(stop: asyncio.Event) -> None:
        from .line import LineDevice, open_line
        from .linepage import LinePage
        from .twin import LiveTwin

        opened, found = await asyncio.to_thread(open_line, port, bauds, ids)
        line = LineDevice(opened, found, poll=poll)
        twin = None
        page: LinePage | None = None
        try:
            if with_twin:
                twin = LiveTwin(machine)
                say(f"coolmuscle: reading {', '.join(f'ID{m}' for m in found.ids)} for the "
                    "twin")
                await twin.prepare(line)
            page = LinePage(line, host, web_port, twin=twin)
            await page.open()
            say(f"coolmuscle: {line.describe()} ready")
            token = f" (token: {page.access.token})" if page.access.token else ""
            extra = f"   twin: {twin.info()['machine']}" if twin is not None else ""
            say(f"web: {page.url}{token}   poll: "
                f"{line.plan.describe() if poll else 'off'}{extra}")
            await stop.wait()
        finally:
            ignore_stop_signals()
            if page is not None:
                await page.close()
            else:
                if twin is not None:
                    await twin.close()
                await line.close()

    run_served(main)


def register(app: typer.Typer) -> None:
    """Add ``web`` to the ``coolmuscle`` command."""
    app.command()(web)

"""The ``check``, ``upload`` and ``term`` subcommands of ``coolmuscle`` (typer).

Registered on the main app by :func:`register` (``coolmuscle.tools.cli.app``).  Exit status as
the rest of the command: 0 success, 1 errors found or a failed upload/connection,
2 bad usage (a missing file, bad options).
"""

from __future__ import annotations

import json
import sys
from enum import Enum
from pathlib import Path
from typing import Any

import typer

from .ports import port_url
from .usage import UsageError

__all__ = ["register"]

#: ``--baud`` as in capture and the desk commands (``--baudrate``: a hidden alias).
_BAUD_HELP = "Baud rate of the motor's port (K20)."
_PORT_HELP = ("The motor: a serial device (/dev/ttyUSB0), HOST:PORT (127.0.0.1:5150, what "
              "'coolmuscle sim' serves) or a pyserial URL (socket://, coolmuscle://).")


class Format(str, Enum):
    human = "human"
    json = "json"
    sarif = "sarif"
    github = "github"


class FirmwareChoice(str, Enum):
    cm2 = "cm2"
    rt3 = "rt3"
    cm1 = "cm1"


def check(
    files: list[Path] = typer.Argument(..., metavar="FILE.cml...", help="CML files to check."),
    output: Format = typer.Option(Format.human, "--format", help="human, json (schema: "
                                  "docs/check-schema.json), sarif (SARIF 2.1.0) or github "
                                  "(GitHub Actions annotations)."),
    junit: Path | None = typer.Option(None, "--junit", metavar="FILE.xml",
                                         help="Also write JUnit XML (a case per finding, "
                                              "with its file and line)."),
    firmware: FirmwareChoice | None = typer.Option(
        None, "--firmware", help="Firmware the file is for (default: its '# coolmuscle: "
        "firmware=' comment, else cm2)."),
    motors: int | None = typer.Option(None, "--motors", min=1, max=15,
                                         help="Motors on the chain (warn beyond)."),
    strict: bool = typer.Option(False, "--strict", help="Warnings fail too."),
) -> None:
    """Lint CML files: syntax, limits, banks, calls, loops, registers."""
    from ...client.program import load_program
    from ..check.lint import check_program
    from ..check.output import format_human, to_json

    _junit_path(junit)
    reports = []
    for path in files:
        if path.is_char_device() or path.is_block_device():  # /dev/zero fills the memory
            raise UsageError(f"cannot read {path}: a device, not a file")
        try:
            program = load_program(path)
        except (OSError, UnicodeDecodeError) as exc:
            raise UsageError(
                f"cannot read {path}: {getattr(exc, 'strerror', None) or exc}") from exc
        try:
            report = check_program(program, firmware=firmware.value if firmware else None,
                                   motors=motors)
        except LookupError:           # the file's own header names no firmware we know
            raise UsageError(f"{path}: '# coolmuscle: firmware={program.firmware}' is not "
                             "cm2, rt3 or cm1") from None
        _check_script_lines(path, report)
        reports.append(report)
    ok = all(r.errors == 0 and not (strict and r.warnings) for r in reports)
    if output is Format.json:
        sys.stdout.write(json.dumps(to_json(reports, strict=strict), indent=2) + "\n")
    elif output is Format.sarif:
        from ..check.ci import to_sarif
        sys.stdout.write(json.dumps(to_sarif(reports, strict=strict), indent=2) + "\n")
    elif output is Format.github:
        from ..check.ci import github_lines
        lines = github_lines(reports, strict=strict) + [format_human(r)[-1] for r in reports]
        sys.stdout.write("".join(line + "\n" for line in lines))
    else:
        for report in reports:
            sys.stdout.write("\n".join(format_human(report)) + "\n")
    if junit is not None:
        from ..check.ci import junit_suites
        from ..ci.junit import write_junit
        write_junit(junit, junit_suites(reports, strict=strict))
    if not ok:
        raise typer.Exit(1)


def _junit_path(path: Path | None) -> None:
    """``--junit`` that cannot be written is bad usage, found before anything runs."""
    from ..ci.junit import path_problem
    problem = None if path is None else path_problem(path)
    if problem is not None:
        raise UsageError(f"cannot write --junit {path}: {problem}")


def _check_script_lines(path: Path, report: Any) -> None:
    """The script lines (``@wait`` ...) as ``coolmuscle run`` reads them: a directive
    ``run`` refuses (``@wiat``) is a ``script`` error here too (docs/scripts.md)."""
    from ...motor.state.firmware import get_firmware
    from ..script.runner import ScriptError, parse_line
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return
    inputs = get_firmware(report.firmware).inputs
    for number, raw in enumerate(text.splitlines(), start=1):
        source = raw.rstrip("\r")
        stripped = source.lstrip()
        if not (stripped[:1] == "@" and stripped[1:2].isalpha()) and \
                not stripped.startswith("<<"):
            continue
        try:
            step = parse_line(stripped, number)
            if step.kind == "input" and step.args[1] > inputs:
                raise ScriptError(f"@input {step.args[1]}: the motor has inputs 1..{inputs} "
                                  f"({report.firmware})", number)
        except ScriptError as exc:
            message = str(exc).split(": ", 1)[1] if str(exc).startswith("line ") else str(exc)
            report.add(number, "script", message)
    report.diagnostics.sort(key=lambda d: (d.line, d.column))


def upload(
    file: Path = typer.Argument(..., metavar="FILE.cml", help="File to send."),
    port: str = typer.Option(..., "--port", metavar="PORT", help=_PORT_HELP),
    save: bool = typer.Option(False, "--save", help="Send $ afterwards (2.1.2)."),
    verify: bool = typer.Option(True, "--verify/--no-verify",
                                help="Read the banks back and compare."),
    baud: int = typer.Option(38400, "--baud", metavar="BPS", help=_BAUD_HELP),
    baudrate: int | None = typer.Option(None, "--baudrate", hidden=True),
    timeout: float = typer.Option(1.0, "--timeout", help="Seconds to wait for each reply."),
    firmware: FirmwareChoice | None = typer.Option(None, "--firmware",
                                                      help="Skip reading ?85."),
) -> None:
    """Send a .cml file to a real or virtual motor and verify it by readback."""
    from ..term.upload import upload_file

    if file.is_dir():
        raise UsageError(f"{file} is a directory, not a .cml file")
    if not file.is_file():
        raise UsageError(f"no such file: {file}")
    result = upload_file(file, port_url(port), save=save, verify=verify,
                         baudrate=baudrate if baudrate is not None else baud,
                         timeout=timeout, firmware=firmware.value if firmware else None,
                         out=sys.stdout, progress=sys.stderr.isatty())
    if not result.ok:
        raise typer.Exit(1)


def term(
    url: str = typer.Argument(..., metavar="PORT", help=_PORT_HELP),
    baud: int = typer.Option(38400, "--baud", metavar="BPS", help=_BAUD_HELP),
    baudrate: int | None = typer.Option(None, "--baudrate", hidden=True),
    motor: int = typer.Option(1, "--motor", min=1, max=15, help="Motor ID for :save/:send."),
    timeout: float = typer.Option(1.0, "--timeout", help="Seconds to wait for replies."),
    history: Path | None = typer.Option(None, "--history", metavar="FILE",
                                           help="History file."),
    log: Path | None = typer.Option(None, "--log", metavar="FILE.cml",
                                       help="Record the session as a golden transcript."),
) -> None:
    """Interactive terminal: line editing, history, colour, :send, :save, :log."""
    from ..term.terminal import main

    main(port_url(url), baudrate=baudrate if baudrate is not None else baud, motor=motor,
         timeout=timeout, history=history, log=log)


def register(app: typer.Typer) -> None:
    """Add ``check``, ``upload`` and ``term`` to the ``coolmuscle`` command."""
    app.command()(check)
    app.command()(upload)
    app.command()(term)

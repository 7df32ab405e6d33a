"""``coolmuscle upload FILE.cml --port URL [--save]``: send a file, verify it by readback.

The file is checked first (``coolmuscle check``'s parser: a file with syntax errors is
not sent), then sent line by line through :meth:`coolmuscle.client.Motor.upload` with a
progress bar on stderr, each bank read back (``?#.n``, ``?L#.n``, 6.6) and compared in
canonical form; every difference is printed as ``B1.1 line 2 (file line 9): expected
'...', motor has '...'``.  ``--save`` then sends ``$`` to every motor the file
addressed and waits for ``saved.n`` (2.1.2).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, TextIO

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

from ...client import connect
from ...client.banks import UploadResult
from ...client.program import BankBlock, ProgramFile, load_program
from ...errors import CoolMuscleError, CoolMuscleTimeout

__all__ = ["upload_file", "motors_of"]


def motors_of(program: ProgramFile) -> list[int]:
    """Motor IDs a file's banks and direct lines address (ID1 when none is named)."""
    from ...client.banks import _motor_of
    ids = {item.motor_id if isinstance(item, BankBlock) else _motor_of(item)
           for item in program.items}
    return sorted(ids or {1})


def upload_file(path: Path, url: str, *, save: bool = False, verify: bool = True,
                baudrate: int = 38400, timeout: float = 1.0, firmware: str | None = None,
                out: TextIO | None = None, progress: bool = True,
                serial_options: dict[str, Any] | None = None) -> UploadResult:
    """Upload ``path`` to the chain at ``url``; print the outcome to ``out``."""
    console = Console(file=out, highlight=False, soft_wrap=True)
    program = load_program(path)
    bad = [line for line in program.source_lines if line.error is not None]
    if bad:
        for line in bad:
            console.print(f"{path}:{line.number}:{line.error.position + 1}: "  # type: ignore[union-attr]
                          f"{str(line.error).split(' at column ')[0]}", markup=False)
        raise CoolMuscleError(f"{path}: {len(bad)} syntax error(s); nothing was sent")
    with connect(url, baudrate=baudrate, timeout=timeout, firmware=firmware,
                 **(serial_options or {})) as motor:
        _check_motors(motor, motors_of(program), url, timeout)
        total = program.send_count()
        bar = Progress(TextColumn("sending"), BarColumn(), MofNCompleteColumn(),
                       console=Console(stderr=True), transient=True, disable=not progress)
        with bar:
            task = bar.add_task("send", total=total)
            result = motor.upload(program, verify=verify, check=False,
                                  progress=lambda done, _total: bar.update(task, completed=done))
        if save and result.ok:
            for motor_id in motors_of(program):
                motor.motor(motor_id).save()
                result.saved.append(motor_id)
        hint = _firmware_hint(path, program.firmware, motor) if not result.ok else None
    _report(console, path, result)
    if hint:
        console.print(hint, markup=False)
    return result


def _check_motors(motor: Any, ids: list[int], url: str, timeout: float) -> None:
    """Every motor ID the file addresses answers ``?99`` before anything is sent: a file
    for ID2 sent to a chain without one stops here, with nothing half sent."""
    for motor_id in ids:
        try:
            motor.motor(motor_id).get_status()
        except CoolMuscleTimeout:
            raise CoolMuscleError(
                f"ID{motor_id} does not answer (no reply to ?99.{motor_id} within "
                f"{timeout:g} s): the chain at {url} has no motor ID{motor_id}, or it is "
                "off or not wired; nothing was sent") from None


def _firmware_hint(path: Path, written_for: str | None, motor: Any) -> str | None:
    """Why banks may be missing: the file names another firmware than the motor's
    (``# coolmuscle: firmware=rt3`` sent to a CM2, whose banks differ: RT3 logic
    motion, U functions, states)."""
    if written_for is None:
        return None
    try:
        actual = motor.version.profile()
    except CoolMuscleError:
        return None
    if actual == written_for:
        return None
    return (f"{path}: hint: the file is written for {written_for} (its '# coolmuscle: "
            f"firmware={written_for}' line) but the motor is {actual} (?85); commands "
            f"of {written_for} that {actual} lacks are refused, so banks come back missing "
            f"or different. Use a motor with {written_for} firmware (coolmuscle sim --firmware "
            f"{written_for}) or a file for {actual}.")


def _report(console: Console, path: Path, result: UploadResult) -> None:
    for line in result.report():
        console.print(f"{path}: {line}", markup=False)
    banks = ", ".join(result.banks) or "no banks"
    verdict = "verified" if result.verified else "not verified"
    if result.ok:
        saved = f"; saved on motor {', '.join(map(str, result.saved))}" if result.saved else ""
        console.print(f"{path}: sent {result.sent} line(s), {banks} {verdict}{saved}",
                      markup=False)
    else:
        console.print(f"{path}: FAILED: {len(result.errors)} error(s), "
                      f"{len(result.differences)} difference(s) after sending "
                      f"{result.sent} line(s)", markup=False)

"""Restore: write a backup to the motors of a line, read back and compare, part by part.

The order of the writes (docs/real-motor.md "Restore"), one *part* at a time:

1. for each motor, ID1 first (K65 written on ID1 is copied to the others, ch. 3 K65):
   its **K parameters** (ch. 3; K37 before the data, whose P range it sets), its
   **data** (the ``\\P``/``\\N`` allocation of 2.1.2 first, 6.2), its **banks**
   (2.2.2, 2.2.3: each bank sent whole and read back);
2. **the line**: K82, K20 and K81 of every motor, ID1 last (they change how the host
   talks to the motors: parity, rate, COM0 protocol); after ID1's K20 the port follows
   the new rate and K20 is read back there;
3. with ``save``, ``$.n`` on each motor (2.1.2: program banks, ladder banks and data are
   kept through a power cycle only once saved; K parameters keep themselves, ch. 3).

Only what differs from the motor is sent.  Each part is read back (the queries of
:mod:`.reading`) and compared with the backup before the next part starts (a motor's K
parameters also when none was written: ID1's K65 is copied to every motor); a part that
fails (an error the motor reports, a value that reads back otherwise, a timeout) stops
the restore, and the :class:`RestoreReport` says which parts were written and verified,
which failed with what, and which were not written.  Nothing is saved then.

:func:`plan_restore` is pure (what to send, from the backup and the motors as read);
:func:`run_restore` sends it through any driver's ``run`` (sync or asyncio in a thread).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

from ...client.banks import save as save_op
from ...client.banks import upload
from ...client.ops import Op, Pause, Session, exchange, fenced, param
from ...client.program import canonical_lines, parse_program
from ...client.protocol import Exchange
from ...device.hostline import BAUD_RATES
from ...errors import CoolMuscleError, MotorError
from ...motor.state.catalogue import same_parameter
from .errors import FirmwareMismatchError
from .image import LINE_PARAMS, ChainImage, MotorImage
from .reading import read_banks, read_data, read_params

__all__ = ["Part", "Outcome", "RestoreReport", "plan_restore", "run_restore",
           "check_restorable", "BATCH"]

Run = Callable[[Op[Any]], Any]
Status = Literal["unchanged", "verified", "failed", "not written", "saved"]

#: Lines sent before each fence (a ``?96`` whose reply says they were all taken): few
#: enough not to flood the motor's buffer (ch. 3 K20 warns of an overflow).
BATCH = 8
#: Seconds the motor takes to answer ``$`` (2.1.2 "saved.n").
SAVE_TIMEOUT = 10.0


@dataclass(frozen=True)
class Part:
    """One part of a restore: what is sent to which motor (``None``: the line)."""

    motor: int | None
    kind: Literal["K parameters", "data", "banks", "line", "save"]
    lines: tuple[str, ...]

    @property
    def name(self) -> str:
        return f"ID{self.motor} {self.kind}" if self.motor is not None else self.kind


@dataclass
class Outcome:
    """What became of one part."""

    part: Part
    status: Status
    problems: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    sent: int = 0

    def line(self) -> str:
        part, total = self.part, len(self.part.lines)
        if self.status == "unchanged":
            return f"{part.name}: as in the backup, nothing to write"
        if self.status == "not written":
            return f"{part.name}: not written ({total} line{'s' if total != 1 else ''})"
        if self.status == "failed":
            done = f" after {self.sent} of {total} line(s)" if total else ""
            return f"{part.name}: FAILED{done}: " + "; ".join(self.problems)
        if self.status == "saved":
            return f"{part.name}: saved"
        notes = "".join(f"; {note}" for note in self.notes)
        return f"{part.name}: {total} line(s) written, read back equal{notes}"


@dataclass
class RestoreReport:
    """Every part of a restore in order, with its outcome."""

    outcomes: list[Outcome] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return all(o.status != "failed" for o in self.outcomes)

    @property
    def failed(self) -> Outcome | None:
        return next((o for o in self.outcomes if o.status == "failed"), None)

    def lines(self) -> list[str]:
        """A line per part up to the one that failed; then the parts not written."""
        out: list[str] = []
        for outcome in self.outcomes:
            out.append(outcome.line())
            if outcome.status == "failed":
                break
        skipped = [o.part.name for o in self.outcomes if o.status == "not written"]
        if skipped:
            out.append("not written: " + ", ".join(skipped) + "; nothing saved ($ not "
                       "sent)")
        return out


# -- what to send ------------------------------------------------------------------------

def check_restorable(backup: ChainImage, live: ChainImage, where: str,
                     name: str = "the backup") -> None:
    """Refuse a backup (called ``name`` in the message) whose motors are not on the line
    ``where``, or are of another firmware."""
    missing = [m for m in backup.ids if m not in live.ids]
    if missing:
        raise FirmwareMismatchError(
            f"{name} holds {_ids(backup.ids)}, {where} answers "
            f"{_ids(live.ids)}: {_ids(tuple(missing))} not on the line; nothing written")
    for saved in backup.motors:
        motor = live.motor(saved.motor)
        if (saved.firmware, saved.version.motor_type) == \
                (motor.firmware, motor.version.motor_type):
            _check_allocation(saved, motor, name, where)
            continue
        other = [k for k in saved.params if not same_parameter(k, saved.firmware,
                                                                motor.firmware)]
        if saved.version.motor_type != motor.version.motor_type:
            other_data = " and the N and R data (R type only)" \
                if "R" in (saved.version.motor_type, motor.version.motor_type) else ""
        else:
            other_data = ""
        applies = (", ".join(f"K{k}" for k in other) + " do not apply there"
                   if other else "its K parameters are the same ones")
        raise FirmwareMismatchError(
            f"{name} holds ID{saved.motor} of {saved.firmware} "
            f"({saved.title}), {where}'s ID{saved.motor} is {motor.firmware} "
            f"({motor.title}): {applies}{other_data}; nothing written")


def _check_allocation(saved: MotorImage, motor: MotorImage, name: str, where: str) -> None:
    """``\\P``/``\\N`` name no motor ID (2.1.2): another motor's allocation cannot be set."""
    if saved.motor == 1 or saved.allocation is None or motor.allocation is None:
        return
    if dict(saved.allocation) != dict(motor.allocation):
        alloc = " ".join(f"{k}{v}" for k, v in saved.allocation.items())
        now = " ".join(f"{k}{v}" for k, v in motor.allocation.items())
        raise FirmwareMismatchError(
            f"{name} holds ID{saved.motor} with {alloc}, {where}'s "
            f"ID{saved.motor} has {now}: \\P and \\N (2.1.2) reach ID1 only; nothing "
            "written")


def _ids(ids: tuple[int, ...]) -> str:
    return ", ".join(f"ID{i}" for i in ids)


def _k_part(saved: MotorImage, motor: MotorImage, k65_copied: bool) -> Part:
    """The K that differ; K65 also when ID1's changes, which copies it here (ch. 3 K65)."""
    m = saved.motor
    lines = tuple(f"K{k}.{m}={v}" for k, v in saved.params.items()
                  if k not in LINE_PARAMS and (motor.params.get(k) != v
                                               or (k == 65 and k65_copied and m != 1)))
    return Part(m, "K parameters", lines)


def _k65_changes(backup: ChainImage, live: ChainImage) -> bool:
    """Whether the restore writes ID1's K65 (which every motor then takes, ch. 3 K65)."""
    if 1 not in backup.ids or 1 not in live.ids:
        return False
    saved = backup.motor(1).params.get(65)
    return saved is not None and saved != live.motor(1).params.get(65)


def _data_part(saved: MotorImage, motor: MotorImage) -> Part:
    m = saved.motor
    lines: list[str] = []
    alloc = saved.allocation
    realloc = alloc is not None and dict(alloc) != dict(motor.allocation or {})
    if realloc and alloc is not None:
        lines += [f"\\P{alloc['P']}", f"\\N{alloc['N']}"]      # ID1 only: check_restorable
    for name, value in saved.data.items():
        resized = realloc and name[0] in "PNR" and name[1:].isdigit()
        if resized or motor.data.get(name) != value:
            lines.append(f"{name}.{m}={value}")
    return Part(m, "data", tuple(lines))


def _same_bank(a: tuple[str, ...], b: tuple[str, ...], motor: int) -> bool:
    return canonical_lines(list(a), motor) == canonical_lines(list(b), motor)


def _banks_part(saved: MotorImage, motor: MotorImage) -> Part:
    """Banks that differ, sent whole; a bank the backup lacks is emptied (the manual has
    no command that deletes one bank, 2.2.2)."""
    m = saved.motor
    lines: list[str] = []
    for label, body in saved.banks.items():
        if label not in motor.banks or not _same_bank(body, motor.banks[label], m):
            lines += [f"{label}.{m}", *body, "END"]
    for label, body in motor.banks.items():
        if label not in saved.banks and body:
            lines += [f"{label}.{m}", "END"]
    return Part(m, "banks", tuple(lines))


def _line_part(backup: ChainImage, live: ChainImage) -> Part:
    lines: list[str] = []
    for saved in sorted(backup.motors, key=lambda i: -i.motor):
        motor = live.motor(saved.motor)
        lines += [f"K{k}.{saved.motor}={saved.params[k]}" for k in LINE_PARAMS
                  if k in saved.params and motor.params.get(k) != saved.params[k]]
    return Part(None, "line", tuple(lines))


def plan_restore(backup: ChainImage, live: ChainImage, *, save: bool = False) -> list[Part]:
    """The parts of a restore, in order (module docstring); empty parts included."""
    parts: list[Part] = []
    k65 = _k65_changes(backup, live)
    for saved in backup.motors:
        motor = live.motor(saved.motor)
        parts += [_k_part(saved, motor, k65), _data_part(saved, motor),
                  _banks_part(saved, motor)]
    parts.append(_line_part(backup, live))
    if save:
        parts += [Part(m, "save", (f"$.{m}",)) for m in backup.ids]
    return parts


# -- sending --------------------------------------------------------------------------

@dataclass
class LineControl:
    """What the port must do when the line changes (ID1's K20 and K82): set the host's
    rate / parity.  A socket has none to set."""

    set_rate: Callable[[int], None] = lambda baud: None
    set_parity: Callable[[int], None] = lambda k82: None


def _send(session: Session, motor: int, lines: tuple[str, ...], outcome: Outcome) -> Op[None]:
    """The lines in batches, each fenced; the motor's errors are collected."""
    for start in range(0, len(lines), BATCH):
        batch = lines[start:start + BATCH]
        try:
            yield from fenced(session, motor, batch)
        except MotorError as error:        # the motor's errorNN.n line (ch. 3 K23 16)
            outcome.problems.append(f"{error} among {batch[0]} .. {batch[-1]}")
        outcome.sent += len(batch)


def _k_check(saved: MotorImage, session: Session) -> Op[list[str]]:
    got = yield from read_params(session, saved.motor, saved.profile)
    return [f"K{k}.{saved.motor} reads {got.get(k)}, the backup has {v}"
            for k, v in saved.params.items() if k not in LINE_PARAMS and got.get(k) != v]


def _data_check(saved: MotorImage, session: Session) -> Op[list[str]]:
    got = yield from read_data(session, saved.motor, saved.profile)
    m = saved.motor
    problems = [f"{name}.{m} reads {got.get(name)}, the backup has {value}"
                for name, value in saved.data.items() if got.get(name) != value]
    extra = [name for name in got if name not in saved.data and name[1:].isdigit()
             and name[0] in "PNR"]
    if extra and saved.allocation is not None:
        problems.append(f"the motor holds {len(extra)} memories the backup has not "
                        f"({extra[0]}..{extra[-1]}: its allocation, 2.1.2)")
    return problems


def _bank_difference(label: str, motor: int, saved: tuple[str, ...],
                     got: tuple[str, ...]) -> str | None:
    """The first line where a bank read back differs from the backup, or ``None``."""
    want, have = canonical_lines(list(saved), motor), canonical_lines(list(got), motor)
    if want == have:
        return None
    i = next(i for i in range(max(len(want), len(have)))
             if i >= len(want) or i >= len(have) or want[i] != have[i])
    backup = repr(want[i]) if i < len(want) else "nothing"
    reads = repr(have[i]) if i < len(have) else "nothing"
    return f"bank {label}.{motor} line {i + 1} reads {reads}, the backup has {backup}"


def _banks_check(saved: MotorImage, session: Session) -> Op[list[str]]:
    got = yield from read_banks(session, saved.motor)
    m = saved.motor
    problems = [diff for label, body in saved.banks.items()
                if (diff := _bank_difference(label, m, body, got.get(label, ()))) is not None]
    problems += [f"bank {label}.{m} is not in the backup and is not empty"
                 for label, body in got.items() if label not in saved.banks and body]
    return problems


def _bank_upload(session: Session, part: Part, outcome: Outcome) -> Op[None]:
    """The banks sent as ``upload`` sends a file (2.2.2, each line paced by its echo)."""
    assert part.motor is not None
    program = parse_program("\n".join(part.lines) + "\n", "backup")
    result = yield from upload(session, program, verify=False)
    outcome.sent = result.sent
    outcome.problems += [str(error) for _line, error in result.errors]   # errorNN.n: ...


def _write_only(text: str) -> Exchange:
    """Write a line and wait for nothing (its answer comes at another rate)."""
    ex = Exchange((text,), lambda _line: True, None, "nothing", timeout=0.0)
    ex.complete = True
    return ex


def _k20(session: Session, motor: int, value: int, asks: bool, control: LineControl,
         outcome: Outcome) -> Op[None]:
    """``K20.n=X``; ``Y`` to the prompt when K23 includes 16 (ch. 3 K23 16); on ID1 the
    port then follows the new rate (ch. 3 K20)."""
    text = f"K20.{motor}={value}"
    if asks:
        yield from exchange(session, (text,), lambda line: line.text.startswith(
            "Change Baud Rate"), motor, "'Change Baud Rate ?? ... (Y/N)'")
        text = "Y"
    if motor != 1:
        yield from fenced(session, motor, (text,))
    else:
        yield _write_only(text)
        yield Pause(0.1)                 # its echo at the old rate
        control.set_rate(BAUD_RATES[value])
    outcome.sent += 1
    got = yield from param(session, motor, 20)
    if got != value:
        outcome.problems.append(f"K20.{motor} reads {got}, the backup has {value}")


def _line_writes(session: Session, part: Part, backup: ChainImage, control: LineControl,
                 outcome: Outcome) -> Op[None]:
    for text in part.lines:
        name, _, value = text.partition("=")
        k, motor = (int(x) for x in name[1:].split("."))
        if k == 20:
            asks = bool(backup.motor(motor).params.get(23, 0) & 16)
            yield from _k20(session, motor, int(value), asks, control, outcome)
        elif k == 81 and int(value) != 0 and motor == 1:
            yield _write_only(text)
            outcome.sent += 1
            outcome.notes.append(f"{text}: COM0 now speaks Modbus RTU (5.6), not read back")
        else:
            yield from fenced(session, motor, (text,))
            if k == 82 and motor == 1:
                control.set_parity(int(value))
            outcome.sent += 1
            got = yield from param(session, motor, k)
            if got != int(value):
                outcome.problems.append(f"K{k}.{motor} reads {got}, the backup has {value}")


def _part_op(session: Session, part: Part, backup: ChainImage, control: LineControl,
             outcome: Outcome) -> Op[None]:
    if part.kind == "line":
        yield from _line_writes(session, part, backup, control, outcome)
        return
    if part.kind == "save":
        assert part.motor is not None
        yield from save_op(session, part.motor, SAVE_TIMEOUT)
        outcome.sent = 1
        outcome.status = "saved"
        return
    assert part.motor is not None
    saved = backup.motor(part.motor)
    if not part.lines:         # K parameters as in the backup: still so after the parts
        outcome.problems += yield from _k_check(saved, session)    # before (K65, ch. 3)
        return
    if part.kind == "banks":
        yield from _bank_upload(session, part, outcome)
        outcome.problems += yield from _banks_check(saved, session)
        return
    yield from _send(session, part.motor, part.lines, outcome)
    check = _k_check if part.kind == "K parameters" else _data_check
    outcome.problems += yield from check(saved, session)


def run_restore(run: Run, session: Session, parts: list[Part], backup: ChainImage, *,
                control: LineControl | None = None,
                progress: Callable[[str], None] | None = None) -> RestoreReport:
    """Send ``parts`` in order through ``run`` (a driver's), stopping at the first part
    that fails; every part gets its outcome in the report."""
    control = control or LineControl()
    report = RestoreReport([Outcome(part, "not written" if part.lines else "unchanged")
                            for part in parts])
    for outcome in report.outcomes:
        part = outcome.part
        if not part.lines and part.kind != "K parameters":
            continue
        if progress is not None:
            progress(f"{part.name}: {len(part.lines)} line(s)")
        outcome.status = "verified" if part.lines else "unchanged"
        try:
            run(_part_op(session, part, backup, control, outcome))
        except CoolMuscleError as exc:
            outcome.problems.append(str(exc))
            outcome.status = "failed"
        if outcome.problems:
            outcome.status = "failed"
        if outcome.status == "failed":
            break
    return report

"""The backup file: a chain's motors as a ``coolmuscle run`` script (docs/real-motor.md).

:func:`render_backup` writes a :class:`~.image.ChainImage` as the lines a host would type
to set the motors up again, in the order :mod:`.restorer` writes them, so that
``coolmuscle run motor.cml`` plays it on a virtual chain (docs/scripts.md) and
``coolmuscle restore`` plays it on a real one::

    # coolmuscle backup of /dev/ttyUSB0 at 38400 bit/s, 2026-01-05T10:00:00Z: 1 motor
    # coolmuscle: motors=1 firmware=cm2
    # == ID1 : CM2v3.10R.1 #0802A12345
    K23.1=17                      the K parameters (ch. 3), but K82, K20, K81
    \\P200                         the allocation (2.1.2, ID1, R type), then the data
    P1.1=1000                     registers (6.2), H0 (5.6.7), the direct data (?.n)
    B1.1 / S1.1, A1.1, P1.1 / END the banks (2.2.2, 2.2.3) as ?1000 lists them
    K82.1=0 / K20.1=0 / Y / K81.1=0   the line, last (``Y`` answers the K20 prompt of
                                  ch. 3 K23 16 when K23 includes 16)

Reserved K numbers are not written (the motor has nothing to set there).
:func:`parse_backup` reads such a file back and checks every line as the motor would
(:func:`~coolmuscle.motor.state.catalogue.k_parameter`, the register ranges of
:class:`~coolmuscle.motor.state.memory.Memory`, the CML parser for bank lines): a line
a motor would refuse is a :class:`~.errors.BackupFileError` naming the line.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

from ...client.replies import parse_version
from ...cml.parser import parse
from ...errors import CmlSyntaxError, OutOfRangeError, ProtocolError
from ...motor.state.firmware import Firmware
from ...motor.state.memory import Memory
from .errors import BackupFileError
from .image import LINE_PARAMS, ChainImage, MotorImage

__all__ = ["render_backup", "parse_backup", "load_backup", "motor_lines", "line_lines"]

_TITLE = re.compile(r"#\s*==\s*(ID\d+ : .*)")
_HOLDS = re.compile(r"# ID(\d+) holds P(\d+) N(\d+) R(\d+):.*")
_SOURCE = re.compile(r"# coolmuscle backup of (.*?)(?: at (\d+) bit/s)?, (\S+): \d+ motors?")
_K = re.compile(r"K(\d+)\.(\d+)=(-?\d+)")
_DATA = re.compile(r"([PNRSAMTVH])(\d*)\.(\d+)=(.*)")
_ALLOC = re.compile(r"\\([PN])(\d+)")
_BANK = re.compile(r"([BL])(\d+)\.(\d+)")
_END = re.compile(r"END(\.\d+)?", re.IGNORECASE)
_NUMBER = re.compile(r"[+-]?\d+")


# -- writing ---------------------------------------------------------------------------

def motor_lines(image: MotorImage) -> list[str]:
    """One motor's section: its K parameters (not the line's), data, banks."""
    m = image.motor
    out = [f"# == {image.title}",
           f"# ID{m} K parameters (ch. 3, table 6.1); K82, K20, K81 at the end"]
    out += [f"K{k}.{m}={v}" for k, v in image.params.items() if k not in LINE_PARAMS]
    out.append(f"# ID{m} data (6.2): allocation (2.1.2), memories, H0, direct mode (?.n)")
    out += _allocation_lines(image)
    out += [f"{name}.{m}={value}" for name, value in image.data.items()]
    out.append(f"# ID{m} banks (?1000)")
    for label, body in image.banks.items():
        out.append(f"{label}.{m}")
        out += list(body)
        out.append("END")
    return out


def _allocation_lines(image: MotorImage) -> list[str]:
    """``\\P`` and ``\\N`` (2.1.2): they name no motor ID, so they reach ID1 only."""
    alloc = image.allocation
    if alloc is None or not image.profile.can_allocate:
        return []
    if image.motor != 1:
        return [f"# ID{image.motor} holds P{alloc['P']} N{alloc['N']} R{alloc['R']}: "
                "\\P and \\N (2.1.2) name no motor ID and reach ID1 only"]
    return [f"\\P{alloc['P']}", f"\\N{alloc['N']}"]


def line_lines(images: tuple[MotorImage, ...]) -> list[str]:
    """K82, K20 (and ``Y`` when K23 includes 16), K81 of every motor, ID1 last."""
    out = ["# The line, last: K82 parity, K20 baud rate, K81 COM0 station (Modbus RTU)"]
    for image in sorted(images, key=lambda i: -i.motor):
        for k in LINE_PARAMS:
            if k in image.params:
                out.append(f"K{k}.{image.motor}={image.params[k]}")
                if k == 20 and image.params.get(23, 0) & 16:
                    out.append("Y")     # ch. 3 K23 16: "Change Baud Rate ?? XXX kbps (Y/N)"
    return out


def render_backup(image: ChainImage) -> str:
    """The backup file of ``image`` (module docstring)."""
    count = len(image.motors)
    where = image.source or "a chain"
    rate = f" at {image.baud} bit/s" if image.baud else ""
    firmware = image.motors[0].firmware if image.motors else "cm2"
    out = [f"# coolmuscle backup of {where}{rate}, {image.taken or '-'}: "
           f"{count} motor{'s' if count != 1 else ''}",
           "# Restore: coolmuscle restore THIS.cml --port PORT [--save]; "
           "play: coolmuscle run THIS.cml",
           f"# coolmuscle: motors={max(image.ids, default=1)} firmware={firmware}"]
    mixed = sorted({m.firmware for m in image.motors} - {firmware})
    if mixed:
        out.append(f"# (also {', '.join(mixed)} on this chain: run plays it all as "
                   f"{firmware})")
    for motor in image.motors:
        out += motor_lines(motor)
    out += line_lines(image.motors)
    return "\n".join(out) + "\n"


# -- reading ---------------------------------------------------------------------------

@dataclass
class _Motor:
    """One motor's lines as read, with their line numbers."""

    title: str
    line: int
    params: dict[int, tuple[int, int]] = field(default_factory=dict)    # k -> (value, line)
    data: dict[str, tuple[str, int]] = field(default_factory=dict)      # name -> (text, line)
    alloc: dict[str, tuple[int, int]] = field(default_factory=dict)     # P/N -> (count, line)
    banks: dict[str, tuple[list[str], int]] = field(default_factory=dict)


class _Reader:
    def __init__(self, name: str) -> None:
        self.name = name
        self.motors: dict[int, _Motor] = {}
        self.bank: tuple[_Motor, str] | None = None
        self.after_k20 = False
        self.source, self.taken = "", ""
        self.baud: int | None = None

    def fail(self, number: int, text: str) -> BackupFileError:
        return BackupFileError(f"{self.name} line {number}: {text}")

    def owner(self, motor: int, number: int) -> _Motor:
        if motor not in self.motors:
            raise self.fail(number, f"ID{motor} has no '# == ID{motor} : ...' title line "
                                    "before it (the firmware of each motor comes from it)")
        return self.motors[motor]

    def line(self, number: int, raw: str) -> None:
        text = raw.strip()
        if self.bank is not None:
            self._bank_line(number, text)
            return
        was_k20, self.after_k20 = self.after_k20, False
        if not text:
            return
        if text.startswith("#"):
            self._comment(number, text)
        elif (k := _K.fullmatch(text)) is not None:
            motor = self.owner(int(k.group(2)), number)
            motor.params[int(k.group(1))] = (int(k.group(3)), number)
            self.after_k20 = k.group(1) == "20"
        elif text in ("Y", "N") and was_k20:
            return                       # the answer to the K20 prompt (ch. 3 K23 16)
        elif (a := _ALLOC.fullmatch(text)) is not None:
            self.owner(1, number).alloc[a.group(1)] = (int(a.group(2)), number)
        elif (d := _DATA.fullmatch(text)) is not None:
            self._data(number, d)
        elif (b := _BANK.fullmatch(text)) is not None:
            motor = self.owner(int(b.group(3)), number)
            label = f"{b.group(1)}{int(b.group(2))}"
            motor.banks[label] = ([], number)
            self.bank = (motor, label)
        else:
            raise self.fail(number, f"not a line of a coolmuscle backup: {text!r}")

    def _comment(self, number: int, text: str) -> None:
        title = _TITLE.fullmatch(text)
        if title is not None:
            try:
                version = parse_version(title.group(1))
            except ProtocolError as exc:
                raise self.fail(number, str(exc)) from None
            if version.motor in self.motors:
                raise self.fail(number, f"ID{version.motor} twice")
            self.motors[version.motor] = _Motor(version.text, number)
            return
        holds = _HOLDS.fullmatch(text)
        if holds is not None:
            motor = self.owner(int(holds.group(1)), number)
            for kind, count in zip("PNR", holds.groups()[1:]):
                motor.alloc[kind] = (int(count), number)
            return
        source = _SOURCE.fullmatch(text)
        if source is not None:
            self.source = source.group(1)
            self.baud = int(source.group(2)) if source.group(2) else None
            self.taken = source.group(3)

    def _data(self, number: int, match: re.Match[str]) -> None:
        kind, index, motor, value = match.groups()
        if kind == "H" and index != "0":
            raise self.fail(number, f"H{index}: only H0 exists (5.6.7)")
        if _NUMBER.fullmatch(value.strip()):
            value = str(int(value))
        elif not (kind == "V" and len(value) >= 2 and value[0] == value[-1] == '"'):
            raise self.fail(number, f"{kind}{index}.{motor}={value}: not a number"
                                    + (" or a quoted text" if kind == "V" else ""))
        self.owner(int(motor), number).data[f"{kind}{index}"] = (value, number)

    def _bank_line(self, number: int, text: str) -> None:
        assert self.bank is not None
        motor, label = self.bank
        if text == "#" or text.startswith("# "):
            return                            # a comment, as coolmuscle run reads it
        if not text or _END.fullmatch(text):
            self.bank = None                  # END, or a blank line (2.2.2)
            return
        try:
            parse(text)
        except CmlSyntaxError as exc:
            raise self.fail(number, f"bank {label}.{_id_of(self, motor)}: {exc}") from None
        motor.banks[label][0].append(text)


def _id_of(reader: _Reader, motor: _Motor) -> int:
    return next(i for i, m in reader.motors.items() if m is motor)


def parse_backup(text: str, name: str = "backup") -> ChainImage:
    """The chain a backup file holds, every line checked (module docstring)."""
    reader = _Reader(name)
    for number, raw in enumerate(text.splitlines(), start=1):
        reader.line(number, raw)
    if reader.bank is not None:
        motor, label = reader.bank
        line = motor.banks[label][1]
        raise reader.fail(line, f"bank {label} has no END")
    if not reader.motors:
        raise BackupFileError(f"{name}: not a coolmuscle backup (no '# == ID1 : ...' "
                              "title line)")
    images = tuple(_checked(reader, motor_id, reader.motors[motor_id])
                   for motor_id in sorted(reader.motors))
    return ChainImage(images, reader.source, reader.baud, reader.taken)


def _checked(reader: _Reader, motor_id: int, motor: _Motor) -> MotorImage:
    image = MotorImage(motor_id, motor.title)
    profile = image.profile
    for k, (value, number) in motor.params.items():
        try:
            problem = image.k(k).problem(value)
        except LookupError as exc:
            problem = str(exc)
        if problem is not None:
            raise reader.fail(number, f"{problem} on {profile.name} (ID{motor_id})")
    memory = _memory(reader, motor, profile)
    for name, (text, number) in motor.data.items():
        _check_value(reader, memory, name, text, number, motor_id)
    top = {"B": profile.program_banks, "L": profile.ladder_banks}
    for label, (_lines, number) in motor.banks.items():
        if not 1 <= int(label[1:]) <= top[label[0]]:
            raise reader.fail(number, f"bank {label}.{motor_id} does not exist on "
                                      f"{profile.name} (1..{top[label[0]]})")
    return MotorImage(motor_id, motor.title,
                      {k: v for k, (v, _n) in sorted(motor.params.items())},
                      {name: text for name, (text, _n) in motor.data.items()},
                      {label: tuple(lines) for label, (lines, _n) in motor.banks.items()},
                      _allocation(memory, motor))


def _allocation(memory: Memory, motor: _Motor) -> dict[str, int] | None:
    """The P, N, R counts the file states (``\\P``/``\\N`` or the ``holds`` line)."""
    if not motor.alloc or not memory.firmware.can_allocate:
        return None
    return {kind: memory.limit(kind) for kind in ("P", "N", "R")}


def _memory(reader: _Reader, motor: _Motor, profile: Firmware) -> Memory:
    k37 = motor.params.get(37, (3, 0))[0]
    memory = Memory(profile, k37=k37)
    for kind in ("P", "N"):
        if kind in motor.alloc:
            count, number = motor.alloc[kind]
            try:
                memory.allocate(kind, count)
            except OutOfRangeError as exc:
                raise reader.fail(number, f"\\{kind}{count}: {exc}") from None
    if "R" in motor.alloc and memory.limit("R") != motor.alloc["R"][0]:
        count, number = motor.alloc["R"]
        raise reader.fail(number, f"R{count} does not add up with P{memory.limit('P')} "
                                  f"N{memory.limit('N')} (2.1.2)")
    return memory


def _check_value(reader: _Reader, memory: Memory, name: str, text: str, number: int,
                 motor_id: int) -> None:
    kind, index = name[0], int(name[1:] or 0)
    shown = f"{name}.{motor_id}={text}"
    if kind in ("N", "R") and not memory.firmware.has_interpolation:
        raise reader.fail(number, f"{shown}: no {kind} data on a "
                                  f"{memory.firmware.motor_type} type motor (R type only, 6.6)")
    if index > memory.limit(kind):
        raise reader.fail(number, f"{shown}: {kind}{index} does not exist on "
                                  f"{memory.firmware.name} ({kind}0..{kind}{memory.limit(kind)})")
    value: int | str = text[1:-1] if text.startswith('"') else int(text)
    try:
        memory.normalise(kind, value)
    except OutOfRangeError as exc:
        raise reader.fail(number, f"{shown}: {exc}") from None


def load_backup(path: str | Path) -> ChainImage:
    """Read and check the backup file at ``path``; :class:`BackupFileError` if it cannot."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except IsADirectoryError:
        raise BackupFileError(f"{path} is a directory, not a backup file") from None
    except OSError as exc:
        raise BackupFileError(f"cannot read {path}: {exc.strerror or exc}") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise BackupFileError(f"{path}: not a text file (byte {exc.start} is not UTF-8)") \
            from None
    return parse_backup(text, str(path))


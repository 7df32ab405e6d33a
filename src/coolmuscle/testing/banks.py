"""A ``.cml`` file sent to a chain in a test, and where each stored bank line came from.

:func:`load_bank_file` sends a file as an upload does (its direct lines run, its bank
definitions ``B#.n`` / ``L#.n`` ... ``END`` stored; :mod:`coolmuscle.client.program`
cuts it), through the device API, then reads each bank back (``?#.n`` / ``?L#.n``, 6.6)
and compares: a bank that stopped loading at a bad line (RT3 3.3 "the bank will cease to
load from that point on") is a :class:`BankLoadError` that names the file's line, with
what ``coolmuscle check`` says of it.

The :class:`BankFile` it returns maps every stored line of every bank (the index ``?#.n``
prints it at) to its line in the file: bank coverage counts file lines with it, and a
failing assertion names the file line that was running (:mod:`.expect`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ..client.program import BankBlock, ProgramFile, load_program
from ..device.api import Device

__all__ = ["BankKey", "BankMap", "BankFile", "BankLoadError", "load_bank_file", "bank_label"]

#: (motor, ladder, bank number)
BankKey = tuple[int, bool, int]


def bank_label(key: BankKey) -> str:
    """``B1.1`` / ``L2.1``."""
    motor, ladder, number = key
    return f"{'L' if ladder else 'B'}{number}.{motor}"


class BankLoadError(AssertionError):
    """A file whose banks the motor did not store as written (the message names the line)."""


@dataclass(frozen=True)
class BankMap:
    """One bank of a file: the file line of each stored line, and its text."""

    key: BankKey
    header_line: int
    lines: tuple[int, ...]          # stored index -> file line number
    texts: tuple[str, ...]          # stored index -> the file line's text

    @property
    def label(self) -> str:
        return bank_label(self.key)


@dataclass
class BankFile:
    """A file loaded on a chain: its path (as given) and its banks by key."""

    path: str
    banks: dict[BankKey, BankMap] = field(default_factory=dict)

    def where(self, key: BankKey, index: int) -> tuple[int, str] | None:
        """(file line, text) of stored line ``index`` of a bank of this file."""
        bank = self.banks.get(key)
        if bank is None or not 0 <= index < len(bank.lines):
            return None
        return bank.lines[index], bank.texts[index]


def _map(block: BankBlock) -> BankMap:
    lines: list[int] = []
    texts: list[str] = []
    for source in block.body:
        # "A; B" on one file line is two stored lines; one that does not parse is sent
        # all the same (and refused by the motor)
        for _ in range(len(source.lines) or (1 if source.error is not None else 0)):
            lines.append(source.number)
            texts.append(source.raw.strip())
    key = (block.motor_id, block.ladder, block.number)
    return BankMap(key, block.header.number, tuple(lines), tuple(texts))


def _stored(device: Device, key: BankKey) -> int:
    motor, ladder, number = key
    return len(device.execute(f"?{'L' if ladder else ''}{number}.{motor}", origin="api"))


def _refused(program: ProgramFile, path: str, bank: BankMap, stored: int,
             firmware: str | None) -> BankLoadError:
    line = bank.lines[stored] if stored < len(bank.lines) else bank.header_line
    text = bank.texts[stored] if stored < len(bank.texts) else ""
    why = ""
    try:
        from ..tools.check.lint import check_program
        report = check_program(program, firmware=firmware)
        found = [d for d in report.diagnostics if d.line == line and d.severity == "error"]
        why = "".join(f"; coolmuscle check: {d.rule}: {d.message}" for d in found)
    except (LookupError, ValueError):
        pass
    return BankLoadError(f"{path}:{line}: the motor stored {stored} of the "
                         f"{len(bank.lines)} lines of {bank.label} and refused `{text}` "
                         f"(a bank stops loading at a bad line, RT3 3.3){why}")


def load_bank_file(device: Device, path: Path, *, shown: str | None = None,
                   firmware: str | None = None) -> BankFile:
    """Send ``path`` to ``device`` (motor 1 takes lines that name none) and check that
    every bank was stored whole; ``shown`` is how messages name the file."""
    name = shown or str(path)
    program = load_program(path)
    loaded = BankFile(name)
    for item in program.items:
        if isinstance(item, BankBlock):
            for text in item.send_lines():
                device.execute(text, origin="api")
            bank = _map(item)
            loaded.banks[bank.key] = bank
            stored = _stored(device, bank.key)
            if stored != len(bank.lines):
                raise _refused(program, name, bank, stored, firmware or program.firmware)
        elif item.error is not None:
            raise BankLoadError(f"{name}:{item.number}: `{item.raw.strip()}` does not "
                                f"parse: {item.error}")
        elif item.lines:
            replies = device.execute(item.send, origin="api")
            bad = [r for r in replies if r.startswith("error")]
            if bad:
                raise BankLoadError(f"{name}:{item.number}: `{item.raw.strip()}`: {bad[0]}")
    return loaded

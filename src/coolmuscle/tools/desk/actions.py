"""What ``coolmuscle scan``, ``backup``, ``restore`` and ``params diff`` do, without the
command-line library (:mod:`.commands` declares them with typer and calls these).

Each returns the exit status: 0 done; 1 a restore that failed part-way, or a diff that
found differences (as diff(1)); bad input raises :class:`~.errors.DeskError` (exit 2,
one line): no motor, a wrong baud rate, a backup of another firmware, a value out of
range in a backup, an unreadable file, an output file that exists.
"""

from __future__ import annotations

import os
import re
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TextIO

from ...device.hostline import BAUD_RATES
from .backupfile import load_backup, render_backup
from .connection import DeskLine, backup, factory_image, restore
from .diff import diff_images, format_diff
from .errors import DeskError
from .image import ChainImage
from .linescan import scan

__all__ = ["parse_ids", "parse_bauds", "do_scan", "do_backup", "do_restore", "do_diff"]

Say = Callable[[str], None]
_RANGE = re.compile(r"(\d+)(?:-(\d+))?")


def parse_ids(text: str | None) -> tuple[int, ...] | None:
    """``--ids 1-3,5`` -> (1, 2, 3, 5); ``None``: the chain from ID1 on."""
    if text is None:
        return None
    ids: set[int] = set()
    for item in text.split(","):
        match = _RANGE.fullmatch(item.strip())
        if match is None:
            raise DeskError(f"--ids takes IDs and ranges such as 1-3,5, not {text!r}")
        lo = int(match.group(1))
        hi = int(match.group(2) or lo)
        if not 1 <= lo <= hi <= 15:
            raise DeskError(f"--ids {text}: motor IDs are 1..15")
        ids.update(range(lo, hi + 1))
    return tuple(sorted(ids))


def parse_bauds(values: Sequence[int] | None) -> tuple[int, ...] | None:
    """``--baud`` values: rates of the K20 table (ch. 3 K20)."""
    if not values:
        return None
    rates = sorted(BAUD_RATES.values())
    for value in values:
        if value not in rates:
            raise DeskError(f"--baud {value} is not a K20 rate (ch. 3 K20: "
                            f"{', '.join(str(r) for r in rates)})")
    return tuple(dict.fromkeys(values))


def do_scan(port: str, bauds: Sequence[int] | None, ids: tuple[int, ...] | None,
            timeout: float, out: TextIO, say: Say, progress: Say | None = None) -> int:
    """Print one line per motor on ``out``; the summary through ``say``."""
    result = scan(port, bauds=bauds, ids=ids, timeout=timeout, progress=progress)
    for line in result.lines():
        out.write(line + "\n")
    say(f"coolmuscle: {result.summary()}")
    return 0


def _write_atomically(path: Path, text: str, force: bool) -> None:
    """Write ``text`` to ``path`` through a temporary file in the same folder; an
    existing file is replaced only with ``force`` (a backup is never lost)."""
    if path.exists() and not force:
        raise DeskError(f"{path} exists (--force replaces it)")
    if path.is_dir():
        raise DeskError(f"{path} is a directory")
    folder = path.parent if str(path.parent) else Path(".")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=folder)
    except OSError as exc:
        raise DeskError(f"cannot write {path}: {exc.strerror or exc}") from None
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        raise DeskError(f"cannot write {path}: {exc.strerror or exc}") from None


def do_backup(port: str, output: Path, bauds: Sequence[int] | None,
              ids: tuple[int, ...] | None, force: bool, say: Say,
              progress: Say | None = None) -> int:
    """Read every motor on ``port`` into the backup file ``output``."""
    if output.exists() and not force:
        raise DeskError(f"{output} exists (--force replaces it)")
    image = backup(port, bauds=bauds, ids=ids, progress=progress)
    _write_atomically(output, render_backup(image), force)
    count = sum(len(m.params) + len(m.data) + len(m.banks) for m in image.motors)
    say(f"coolmuscle: {output}: {_ids(image)} ({count} values and banks) of {image.source}")
    return 0


def _ids(image: ChainImage) -> str:
    return ", ".join(f"ID{m.motor} {m.firmware}" for m in image.motors)


def do_restore(file: Path, port: str, bauds: Sequence[int] | None, save: bool, out: TextIO,
               say: Say, progress: Say | None = None) -> int:
    """Write the backup ``file`` to the motors on ``port``; one line per part."""
    image = load_backup(file)
    report = restore(image, port, bauds=bauds, save=save, name=str(file), progress=progress)
    for line in report.lines():
        out.write(line + "\n")
    if not report.ok:
        say(f"coolmuscle: restore of {file} failed at {report.failed.part.name}"
            if report.failed else "coolmuscle: restore failed")
        return 1
    if not save:
        say("coolmuscle: restored; data and banks are kept through a power cycle only "
            "after $ (restore --save; 2.1.2)")
    return 0


def _side(text: str, bauds: Sequence[int] | None, other: ChainImage | None,
          progress: Say | None) -> tuple[ChainImage | None, str]:
    """A backup file, ``factory[:FIRMWARE]`` (made later, like the other side), or a
    port read live."""
    if text == "factory" or text.startswith("factory:"):
        return None, text
    path = Path(text)
    if path.is_file() or path.suffix.lower() == ".cml":
        return load_backup(path), text
    with DeskLine(text, bauds=bauds, ids=other.ids if other else None,
                  progress=progress) as line:
        return line.read_chain(progress=progress), text


def _factory(text: str, like: ChainImage) -> ChainImage:
    firmware = text.partition(":")[2].strip().lower() or None
    if firmware is not None and firmware not in ("cm2", "rt3", "cm1"):
        raise DeskError(f"{text}: the firmware is cm2, rt3 or cm1")
    return factory_image(like, firmware)


def do_diff(a: str, b: str, everything: bool, bauds: Sequence[int] | None, out: TextIO,
            progress: Say | None = None) -> int:
    """Print the differences from A to B; 0 when there is none, 1 otherwise."""
    first, a_name = _side(a, bauds, None, progress)
    second, b_name = _side(b, bauds, first, progress)
    if first is None and second is None:
        raise DeskError("one side of params diff must be a backup or a port, not both "
                        "factory")
    if first is None:
        assert second is not None
        first = _factory(a, second)
    if second is None:
        second = _factory(b, first)
    diffs = diff_images(first, second, everything=everything)
    for line in format_diff(diffs, first, second, a_name, b_name, everything=everything):
        out.write(line + "\n")
    return 1 if diffs else 0

"""``coolmuscle params diff A B``: the differences between two images of a chain.

Each side is a backup file, ``factory`` (the factory values of each motor's firmware)
or a live line (:mod:`.connection` makes the images).  The K parameters are compared
one by one and each difference is shown with what the parameter is (the catalogue of
:mod:`coolmuscle.motor.state.catalogue`: table 6.1's meaning, unit, range, factory
value); with ``everything`` the data registers and banks too.  A K number that is
another parameter on the other side's firmware (K85: CM2 endian, RT3 power-up logic
bank) is a difference whatever the values.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from ...client.program import canonical_lines
from ...motor.state.catalogue import KParameter, same_parameter
from .image import ChainImage, MotorImage

__all__ = ["Difference", "diff_images", "format_diff"]


@dataclass(frozen=True)
class Difference:
    """One difference: motor, what (``K24``, ``P15``, ``B1``, or the motor itself),
    the value on each side (``None``: not there) and, for a K, its catalogue entry."""

    motor: int
    kind: Literal["motor", "K", "data", "bank"]
    name: str
    a: str | None
    b: str | None
    k: KParameter | None = None
    other: KParameter | None = None

    def lines(self) -> list[str]:
        where = f"ID{self.motor} {self.name}" if self.kind != "motor" else f"ID{self.motor}"
        change = f"{_shown(self.a)} -> {_shown(self.b)}"
        if self.k is None:
            return [f"{where}: {change}"]
        if self.other is not None:
            return [f"{where}: {change}   not the same parameter: "
                    f"{self.k.firmware} {self.k.describe()} / "
                    f"{self.other.firmware} {self.other.describe()}"]
        return [f"{where}: {change}   {self.k.describe()}", f"    {self.k.meaning}"]


def _shown(value: str | None) -> str:
    return "(none)" if value is None else value


def _k_differences(a: MotorImage, b: MotorImage) -> list[Difference]:
    out: list[Difference] = []
    for k in sorted(set(a.params) | set(b.params)):
        va, vb = a.params.get(k), b.params.get(k)
        ka = a.k(k) if k in a.params else b.k(k)
        same = same_parameter(k, a.firmware, b.firmware)
        if va == vb and same:
            continue
        other = None if same or va is None or vb is None else b.k(k)
        out.append(Difference(a.motor, "K", f"K{k}", _text(va), _text(vb), ka, other))
    return out


def _text(value: int | None) -> str | None:
    return None if value is None else str(value)


def _data_differences(a: MotorImage, b: MotorImage) -> list[Difference]:
    names = list(a.data) + [n for n in b.data if n not in a.data]
    return [Difference(a.motor, "data", name, a.data.get(name), b.data.get(name))
            for name in names if a.data.get(name) != b.data.get(name)]


def _bank_text(body: tuple[str, ...] | None) -> str | None:
    if body is None:
        return None
    return f"{len(body)} line{'s' if len(body) != 1 else ''}"


def _bank_differences(a: MotorImage, b: MotorImage) -> list[Difference]:
    out: list[Difference] = []
    for label in list(a.banks) + [n for n in b.banks if n not in a.banks]:
        ba, bb = a.banks.get(label), b.banks.get(label)
        if canonical_lines(list(ba or ()), a.motor) == canonical_lines(list(bb or ()), a.motor):
            continue                       # an empty bank is no bank (2.2.2)
        out.append(Difference(a.motor, "bank", label, _bank_text(ba), _bank_text(bb)))
    return out


def diff_images(a: ChainImage, b: ChainImage, *, everything: bool = False) -> list[Difference]:
    """The differences from ``a`` to ``b``, motor by motor in ID order."""
    out: list[Difference] = []
    for motor in sorted(set(a.ids) | set(b.ids)):
        if motor not in b.ids or motor not in a.ids:
            title = (a if motor in a.ids else b).motor(motor).title
            out.append(Difference(motor, "motor", "", title if motor in a.ids else None,
                                  title if motor in b.ids else None))
            continue
        ma, mb = a.motor(motor), b.motor(motor)
        out += _k_differences(ma, mb)
        if everything:
            out += _data_differences(ma, mb) + _bank_differences(ma, mb)
    return out


def format_diff(diffs: list[Difference], a: ChainImage, b: ChainImage, a_name: str,
                b_name: str, *, everything: bool = False) -> list[str]:
    """The report: a header per side, each difference, a count."""
    out = [f"--- {a_name}: {_motors(a)}", f"+++ {b_name}: {_motors(b)}"]
    for diff in diffs:
        out += diff.lines()
    what = "K parameters, data and banks" if everything else "K parameters"
    count = len(diffs)
    out.append(f"{count} difference{'s' if count != 1 else ''} in the {what}"
               if count else f"no difference in the {what}")
    return out


def _motors(image: ChainImage) -> str:
    return "; ".join(f"ID{m.motor} {m.firmware} ({m.title})" for m in image.motors)

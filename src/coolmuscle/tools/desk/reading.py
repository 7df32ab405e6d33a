"""Reading a motor into a :class:`~.image.MotorImage`: sans-IO operations (queries only).

Each function is an operation of :mod:`coolmuscle.client.ops`: a generator that yields
requests, run by the blocking driver (:class:`coolmuscle.client.driver.SyncDriver`) or
the asyncio one (:class:`coolmuscle.client.aio_driver.AsyncDriver`), so the command line
and a web page read a motor the same way.  The queries (6.6; nothing is changed):

* ``?85.n`` the title; ``?90.n`` K20..K89 (ch. 3);
* ``?P.n`` ``?N.n`` ``?R.n`` (R type only, 6.6) ``?S.n`` ``?A.n`` ``?M.n`` ``?T.n``
  ``?V.n``; ``H0.n`` (5.6.7; kept only where the motor answers it); ``?.n`` the
  direct-mode data;
* ``?1000.n`` every program and ladder bank.
"""

from __future__ import annotations

import re
from dataclasses import replace

from ...client.banks import all_banks
from ...client.ops import Op, Session, exchange, fenced, listing, params
from ...errors import MotorError, ProtocolError
from ...motor.state.firmware import Firmware
from .errors import DeskError
from .image import DIRECT_KINDS, MEMORY_KINDS, MotorImage, split_items

__all__ = ["version_title", "read_params", "read_data", "read_banks", "read_motor",
           "memory_kinds"]


def version_title(session: Session, motor: int, timeout: float | None = None) -> Op[str]:
    """``?85.n``: the version title (6.6), or a line that starts ``IDn :`` in another form."""
    start = re.compile(rf"ID{motor}\s*:")
    ex = yield from exchange(session, (f"?85.{motor}",),
                             lambda line: start.match(line.text) is not None,
                             motor, "?85 version title", timeout)
    return ex.lines[-1].text


def read_params(session: Session, motor: int, profile: Firmware) -> Op[dict[int, int]]:
    """``?90.n``: the K parameters ``profile`` defines (reserved numbers left out)."""
    values = yield from params(session, motor)
    return {k: v for k, v in sorted(values.items()) if not _reserved(profile, k)}


def _reserved(profile: Firmware, k: int) -> bool:
    try:
        return profile.spec(k).reserved
    except KeyError:
        return True


def memory_kinds(profile: Firmware) -> tuple[str, ...]:
    """The registers with memory numbers the motor has: N and R on the R type only."""
    return tuple(kind for kind in MEMORY_KINDS
                 if kind not in ("N", "R") or profile.has_interpolation)


def _listed(session: Session, motor: int, query: str) -> Op[list[tuple[str, str]]]:
    """A listing query's ``(name, value)`` items for ``motor``."""
    lines = yield from listing(session, motor, query)
    items: list[tuple[str, str]] = []
    for line in lines:
        for name, owner, value in split_items(line):
            if owner != motor:
                raise ProtocolError(f"{query} answered for ID{owner}: {line!r}")
            items.append((name, value))
    return items


def read_data(session: Session, motor: int, profile: Firmware) -> Op[dict[str, str]]:
    """The data registers, in the order a restore writes them (:mod:`.image`)."""
    data: dict[str, str] = {}
    for kind in memory_kinds(profile):
        for name, value in (yield from _listed(session, motor, f"?{kind}.{motor}")):
            data[name] = value
    h0 = yield from _read_h0(session, motor)
    if h0 is not None:
        data["H0"] = h0
    for name, value in (yield from _listed(session, motor, f"?.{motor}")):
        if name in DIRECT_KINDS:
            data[name] = value
    return data


def _read_h0(session: Session, motor: int) -> Op[str | None]:
    """``H0.n`` (5.6.7 servo stiffness), or ``None`` where the motor does not answer it."""
    try:
        answer = yield from fenced(session, motor, (f"H0.{motor}",))
    except MotorError:
        return None
    for line in answer[:-1]:
        if line.name == "H0" and line.motor == motor and line.value is not None:
            return line.value
    return None


def read_banks(session: Session, motor: int) -> Op[dict[str, tuple[str, ...]]]:
    """``?1000.n``: every bank, ``{"B1": lines, "L2": lines}`` in the listing's order."""
    banks = yield from all_banks(session, motor)
    out: dict[str, tuple[str, ...]] = {}
    for label, lines in banks.items():
        name, _, owner = label.partition(".")
        if owner.isdigit() and int(owner) == motor:
            out[name] = tuple(lines)
    return out


def read_motor(session: Session, motor: int) -> Op[MotorImage]:
    """Everything a backup holds of motor ID ``motor``."""
    title = yield from version_title(session, motor)
    image = MotorImage(motor, title)
    try:
        profile = image.profile
    except ProtocolError:
        raise DeskError(f"ID{motor} answers ?85 with {title!r}, which does not say its "
                        "firmware (6.6 ?85: ID1 : CM2v3.10R.1 #...); cm2, rt3 and cm1 are "
                        "known") from None
    values = yield from read_params(session, motor, profile)
    data = yield from read_data(session, motor, profile)
    banks = yield from read_banks(session, motor)
    image = MotorImage(motor, title, values, data, banks)
    if profile.can_allocate:
        return replace(image, allocation=image.counted_allocation())
    return image

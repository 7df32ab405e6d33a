"""The page's desk: the K-parameter editor, the motor buttons, scan, backup and restore.

One set of requests for the virtual page and for the page of a real motor (the same
JavaScript asks them): each is checked here, then run as the client operations of
:mod:`.pageops` or of the desk (:mod:`coolmuscle.tools.desk`) by a :class:`Runner`,
the page's line to the chain:

* :class:`ChainRunner` for a served chain: the operations run in the model's thread on
  the device (:class:`EchoLink`), at one instant, as the bank upload does;
* :class:`.line.LineDevice` for a serial line (or a socket): the asyncio driver of the
  host library, the user's requests before the poll.

Requests (``{"t": KIND, "id": N, ...}``; the answer is the page's usual ``result``):

=============  ==========================================================================
``k_table``    ``motor``: every K of the firmware with the motor's value (``?90.n``)
``k_write``    ``motor``, ``k``, ``value``: ``K#.n=v`` read back; refused unsent when
               out of range (the catalogue's reason), the motor's own error otherwise
``save``       ``motor``: ``$.n`` (2.1.2)
``motion``     ``motor``, ``what`` (``jog+``, ``jog-``, ``enable``, ``free``, ``stop``,
               ``alarm_reset``), ``step`` and ``speed`` for a jog
``scan``       ``bauds`` (a list of K20 rates, or none: every rate): the motors that
               answer (docs/real-motor.md "Scan")
``backup``     the backup file of every motor (docs/real-motor.md "Backup")
``restore``    ``text`` (a backup file), ``save``: the restore report
=============  ==========================================================================
"""

from __future__ import annotations

import asyncio
import datetime
import logging
import math
from collections.abc import Awaitable, Callable
from typing import Any, Protocol, TypeVar

from ...client.ops import Op, Session, status
from ...device import Device
from ...device.hostline import BAUD_RATES
from ...errors import CoolMuscleError, MotorError
from ...frontends.transports.base import Port
from ..desk.backupfile import parse_backup, render_backup
from ..desk.errors import DeskError
from ..desk.image import ChainImage, MotorImage
from ..desk.restorer import LineControl, RestoreReport, check_restorable, plan_restore, run_restore
from .actions import RequestError
from .banks import DeviceLink, firmware_of
from .hub import Note
from .pageops import (
    MOTIONS,
    at_rest,
    find_motors,
    k_table,
    k_write,
    motion,
    read_images,
    save_params,
    status_text,
)

log = logging.getLogger(__name__)

T = TypeVar("T")
R = TypeVar("R")

#: The requests of this module.
KINDS = frozenset({"k_table", "k_write", "save", "motion", "scan", "backup", "restore"})
#: Largest backup text a page may send (15 motors of about 8 KB each, with room).
MAX_BACKUP_TEXT = 200 * 1024
#: Longest jog (pulses): the widest position range of 6.2 (K37 80-90, ±2^31).
MAX_JOG = 2**31 - 1
#: Run: drives one client operation to its end, in the caller's thread.
Run = Callable[[Op[Any]], Any]


class Runner(Protocol):
    """The page's line to a chain, as the desk uses it."""

    @property
    def motor_ids(self) -> tuple[int, ...]: ...

    @property
    def session(self) -> Session:
        """The client session the operations run in."""
        ...

    @property
    def where(self) -> str:
        """The line in messages: ``/dev/ttyUSB0``, ``the virtual chain``."""
        ...

    @property
    def baud(self) -> int | None:
        """The line's rate (``None``: no wire)."""
        ...

    def firmware_of(self, motor: int) -> str: ...

    async def run(self, op: Op[T]) -> T:
        """One client operation, before the poll."""
        ...

    async def drive(self, work: Callable[[Run, LineControl], R]) -> R:
        """``work`` drives operations one after the other (a restore), the line held."""
        ...

    async def scan(self, bauds: tuple[int, ...] | None) -> dict[str, Any]:
        """Which motors answer (``lines``, ``summary``); may change :attr:`motor_ids`."""
        ...


class EchoLink(DeviceLink):
    """The bank upload's link to a device, with each line's echo in front of its replies.

    ``Device.execute`` returns the replies alone; a line a host types comes back first
    as its echo (ch. 3 K23 8 off).  Fed as the host line would print it, the client's
    protocol never takes a reply equal to a line sent (``K24.1=2000`` after
    ``K24.1=2000``, ``K24.1``) for that line's echo."""

    echo = True


class ChainRunner:
    """The desk on a served chain: operations in the model's thread, at one instant."""

    def __init__(self, port: Port, device: Device, note: Note) -> None:
        self.port = port
        self.device = device
        self.link = EchoLink(device, device.motor_ids[0], note)

    @property
    def motor_ids(self) -> tuple[int, ...]:
        return tuple(self.device.motor_ids)

    @property
    def session(self) -> Session:
        return self.link.session

    @property
    def where(self) -> str:
        return "the virtual chain"

    @property
    def baud(self) -> int | None:
        return None

    def firmware_of(self, motor: int) -> str:
        firmware = firmware_of(self.device)
        return firmware.name if firmware is not None else "cm2"

    def _run_now(self, op: Op[T]) -> T:
        result: T = self.port.call(self.link.run, op)
        return result

    async def run(self, op: Op[T]) -> T:
        return self._run_now(op)

    async def drive(self, work: Callable[[Run, LineControl], R]) -> R:
        return work(self._run_now, LineControl())

    async def scan(self, bauds: tuple[int, ...] | None) -> dict[str, Any]:
        found = await self.run(find_motors(self.link.session))
        count = len(found)
        return {"lines": [m.line() for m in found],
                "summary": f"{count} motor{'s' if count != 1 else ''} on {self.where} "
                           "(no wire, no rate)"}


class Desk:
    """Handles the desk's requests (module docstring) through a :class:`Runner`."""

    def __init__(self, runner: Runner, note: Note, now: Callable[[], int]) -> None:
        self.runner = runner
        self._note = note
        self._now = now
        self._long = asyncio.Lock()      # one scan, backup or restore at a time

    @staticmethod
    def handles(kind: object) -> bool:
        return isinstance(kind, str) and kind in KINDS

    def say(self, text: str) -> None:
        """A note in every page's log."""
        self._note([self._now(), "note", text, 0, "web"])

    async def handle(self, request: dict[str, Any]) -> dict[str, Any]:
        """Answer one request (never raises)."""
        rid = request.get("id")
        rid = rid if isinstance(rid, (int, str)) and not isinstance(rid, bool) else None
        kind = str(request.get("t"))
        try:
            if kind not in KINDS:
                raise RequestError(f"unknown request {kind[:40]!r}")
            handler: Callable[[dict[str, Any]], Awaitable[dict[str, Any]]] = \
                getattr(self, "_" + kind)
            answer = await handler(request)
            return {"t": "result", "id": rid, "ok": True, **answer}
        except MotorError as exc:
            return {"t": "result", "id": rid, "ok": False,
                    "error": f"the motor refused it: {exc}"}
        except (CoolMuscleError, ValueError, LookupError) as exc:
            return {"t": "result", "id": rid, "ok": False, "error": str(exc) or type(exc).__name__}
        except Exception:
            log.exception("desk request %r failed", kind)
            return {"t": "result", "id": rid, "ok": False,
                    "error": "internal error (logged by coolmuscle)"}

    # -- arguments ----------------------------------------------------------
    def _motor(self, request: dict[str, Any]) -> int:
        motor = request.get("motor", 1)
        ids = self.runner.motor_ids
        if not _is_int(motor) or motor not in ids:
            shown = f"IDs {ids[0]}..{ids[-1]}" if ids else "no motor"
            raise RequestError(f"no motor ID{motor} on {self.runner.where} ({shown})")
        return int(motor)

    @staticmethod
    def _int(request: dict[str, Any], name: str, lo: int, hi: int,
             default: int | None = None) -> int | None:
        value = request.get(name, default)
        if value is None:
            return None
        if isinstance(value, float) and math.isfinite(value) and value.is_integer():
            value = int(value)
        if not _is_int(value) or not lo <= value <= hi:
            raise RequestError(f"{name} must be a whole number {lo}..{hi}")
        return int(value)

    # -- the K parameters ---------------------------------------------------
    async def _k_table(self, request: dict[str, Any]) -> dict[str, Any]:
        motor = self._motor(request)
        return await self.runner.run(k_table(_session(self), motor,
                                             self.runner.firmware_of(motor)))

    async def _k_write(self, request: dict[str, Any]) -> dict[str, Any]:
        motor = self._motor(request)
        k = self._int(request, "k", 0, 99)
        value = self._int(request, "value", -2**31, 2**31 - 1)
        if k is None or value is None:
            raise RequestError("k_write needs k and value")
        return await self.runner.run(k_write(_session(self), motor,
                                             self.runner.firmware_of(motor), k, value))

    async def _save(self, request: dict[str, Any]) -> dict[str, Any]:
        return await self.runner.run(save_params(_session(self), self._motor(request)))

    async def _motion(self, request: dict[str, Any]) -> dict[str, Any]:
        motor, what = self._motor(request), request.get("what")
        if what in ("jog+", "jog-"):
            step = self._int(request, "step", 1, MAX_JOG, 100)
            speed = self._int(request, "speed", 1, 2**31 - 1)
            assert step is not None
            return await self.runner.run(motion(_session(self), motor, what, step, speed))
        if what not in MOTIONS:
            raise RequestError(f"unknown button {str(what)[:20]!r} (jog+, jog-, "
                               f"{', '.join(MOTIONS)})")
        return await self.runner.run(motion(_session(self), motor, str(what)))

    # -- scan, backup, restore ----------------------------------------------
    async def _scan(self, request: dict[str, Any]) -> dict[str, Any]:
        bauds = request.get("bauds")
        rates = sorted(BAUD_RATES.values())
        if bauds is not None and not (isinstance(bauds, list) and bauds
                                      and all(_is_int(b) and b in rates for b in bauds)):
            raise RequestError("bauds: K20 rates (ch. 3 K20: "
                               f"{', '.join(str(r) for r in rates)}) or none for all")
        async with self._busy("scan"):
            return await self.runner.scan(tuple(bauds) if bauds else None)

    async def _backup(self, _request: dict[str, Any]) -> dict[str, Any]:
        async with self._busy("backup"):
            taken = _now_text()
            self.say(f"backup: reading {_ids(self.runner.motor_ids)} of {self.runner.where}")
            image = await self.runner.run(read_images(
                _session(self), self.runner.motor_ids, self.runner.where, self.runner.baud,
                taken))
            text = render_backup(image)
            stamp = taken.replace(":", "").replace("-", "")
            return {"text": text, "name": f"coolmuscle-backup-{stamp}.cml",
                    "summary": ", ".join(f"ID{m.motor} {m.firmware}" for m in image.motors)
                    + f" ({sum(len(m.params) + len(m.data) + len(m.banks) for m in image.motors)}"
                    " values and banks)"}

    async def _restore(self, request: dict[str, Any]) -> dict[str, Any]:
        text, save = request.get("text"), request.get("save", False)
        name = request.get("name", "the backup")
        if not isinstance(text, str) or not isinstance(save, bool) \
                or not isinstance(name, str):
            raise RequestError("restore needs the backup's text, save true or false")
        if len(text) > MAX_BACKUP_TEXT:
            raise RequestError(f"backup too large ({len(text)} characters, at most "
                               f"{MAX_BACKUP_TEXT})")
        name = name[:80] or "the backup"
        image = parse_backup(text, name)          # each line checked (BackupFileError)
        async with self._busy("restore"):
            report = await self._restore_image(image, save, name)
        for line in report.lines():
            self.say(f"restore: {line}")
        return {"restored": report.ok, "lines": report.lines(), "saved": save and report.ok}

    async def _restore_image(self, image: ChainImage, save: bool, name: str) -> RestoreReport:
        runner = self.runner
        here = ChainImage(tuple(MotorImage(m, "") for m in runner.motor_ids), runner.where)
        missing = [m for m in image.ids if m not in here.ids]
        if missing:
            check_restorable(image, here, runner.where, name)
        self.say(f"restore: reading {_ids(image.ids)} of {runner.where}")
        live = await runner.run(read_images(_session(self), image.ids, runner.where,
                                            runner.baud, ""))
        check_restorable(image, live, runner.where, name)
        for motor in image.ids:
            ux = int(await runner.run(status(_session(self), motor)))
            if not at_rest(ux):
                raise DeskError(f"ID{motor} is moving ({status_text(ux)}): stop it before a "
                                "restore (ch. 3: do not change parameters during motion)")
        parts = plan_restore(image, live, save=save)

        def work(run: Run, control: LineControl) -> RestoreReport:
            return run_restore(run, _session(self), parts, image, control=control,
                               progress=lambda text: None)
        return await runner.drive(work)

    def _busy(self, what: str) -> _Busy:
        return _Busy(self._long, what)


class _Busy:
    """One scan, backup or restore at a time: another is refused, not queued."""

    def __init__(self, lock: asyncio.Lock, what: str) -> None:
        self.lock = lock
        self.what = what

    async def __aenter__(self) -> None:
        if self.lock.locked():
            raise RequestError(f"a scan, backup or restore is running: {self.what} again "
                               "when it has ended")
        await self.lock.acquire()

    async def __aexit__(self, *exc: object) -> None:
        self.lock.release()


def _session(desk: Desk) -> Session:
    return desk.runner.session


def _ids(ids: tuple[int, ...]) -> str:
    return ", ".join(f"ID{m}" for m in ids)


def _now_text() -> str:
    return datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)

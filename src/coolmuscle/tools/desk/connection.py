"""The desk's blocking entry points: a line to a chain, a backup, a restore, the images a
diff compares (docs/real-motor.md).  A web page runs them in a worker thread; the
sans-IO parts they are made of (:mod:`.reading`, :mod:`.restorer`) run on its asyncio
driver as well.

:class:`DeskLine` opens PORT, finds the rate and the motors with a scan (:mod:`.linescan`,
queries only) and keeps the port at that rate with a client session
(:class:`coolmuscle.client.driver.SyncDriver`) to read and write through.
"""

from __future__ import annotations

import datetime
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

from ...client.driver import SyncDriver
from ...client.ops import Op, Session, status
from ...device.hostline import BAUD_RATES
from ...motor.status import ALARM_BITS, Ux
from .errors import DeskError
from .image import ChainImage, MotorImage
from .linescan import REPLY_TIMEOUT, SCAN_ORDER, ScanResult, scan_port
from .ports import open_port, port_url
from .reading import read_motor
from .restorer import LineControl, RestoreReport, check_restorable, plan_restore, run_restore

__all__ = ["DeskLine", "backup", "restore", "factory_image", "listing_timeout"]

T = TypeVar("T")
Progress = Callable[[str], None]

#: Bytes of the longest listing a motor prints (CM2 ``?P``: 200 items, echo and fence).
LONGEST_LISTING = 4000
#: Ux bits of a motor at rest (6.6 ?99): in position, free, an alarm, stopped.
AT_REST = int(Ux.IN_POSITION | Ux.MOTOR_FREE | ALARM_BITS | Ux.EMERGENCY_STOP | Ux.PUSH_ERROR)


def listing_timeout(baud: int) -> float:
    """Seconds to allow one exchange: the longest listing twice over at ``baud``, + 1 s."""
    return 1.0 + 2 * LONGEST_LISTING * 10 / baud


class DeskLine:
    """An open line to a chain at the rate a scan found (module docstring)."""

    def __init__(self, port: str, *, bauds: Sequence[int] | None = None,
                 ids: Sequence[int] | None = None, timeout: float = REPLY_TIMEOUT,
                 progress: Progress | None = None) -> None:
        self.url = port_url(port)
        rates = tuple(bauds) if bauds else SCAN_ORDER
        self.port: Any = open_port(self.url, rates[0])
        try:
            self.scan: ScanResult = scan_port(self.port, self.url, bauds=rates, ids=ids,
                                              timeout=timeout, progress=progress)
        except BaseException:
            self.port.close()
            raise
        first = self.scan.motors[0].k20
        self.rate = self.scan.baud or BAUD_RATES.get(first if first is not None else 0, 38400)
        self.session = Session(timeout=listing_timeout(self.rate))
        self.driver = SyncDriver(self.port, self.session)
        self.port.reset_input_buffer()

    def __enter__(self) -> DeskLine:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self.port.close()

    def run(self, op: Op[T]) -> T:
        """Run a client operation on this line."""
        return self.driver.run(op)

    def read_chain(self, ids: Sequence[int] | None = None,
                   progress: Progress | None = None) -> ChainImage:
        """Every motor the scan found (or those of ``ids`` it found), read whole."""
        motors: list[MotorImage] = []
        for motor in self.scan.ids:
            if ids is None or motor in ids:
                if progress is not None:
                    progress(f"reading ID{motor}")
                motors.append(self.run(read_motor(self.session, motor)))
        taken = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
        return ChainImage(tuple(motors), self.url, self.scan.baud, taken)

    def _at_rest(self, ids: Sequence[int]) -> None:
        """ch. 3: "Do not change parameters during motion"."""
        for motor in ids:
            ux = int(self.run(status(self.session, motor)))
            if not ux & AT_REST:
                raise DeskError(f"ID{motor} is moving (Ux.{motor}={ux}): stop it before a "
                                "restore (ch. 3: do not change parameters during motion)")

    def _set_rate(self, baud: int) -> None:
        if self.scan.baud is not None:           # a wire: follow the motor
            self.port.baudrate = baud
        self.rate = baud

    def _set_parity(self, k82: int) -> None:
        if self.scan.baud is not None:
            self.port.parity = "NEO"[k82 % 3]    # K82: 0 none, 1 even, 2 odd

    def restore(self, backup: ChainImage, *, save: bool = False, name: str = "the backup",
                progress: Progress | None = None) -> RestoreReport:
        """Write ``backup`` (``name`` in messages) to the motors of this line (:mod:`.restorer`)."""
        live_ids = ChainImage(tuple(MotorImage(m.motor, m.title) for m in self.scan.motors))
        check_restorable(backup, live_ids, self.url, name)     # IDs and titles, before reading
        live = self.read_chain(backup.ids, progress)
        check_restorable(backup, live, self.url, name)
        self._at_rest(backup.ids)
        parts = plan_restore(backup, live, save=save)
        return run_restore(self.run, self.session, parts, backup,
                           control=LineControl(self._set_rate, self._set_parity),
                           progress=progress)


def backup(port: str, *, bauds: Sequence[int] | None = None,
           ids: Sequence[int] | None = None, progress: Progress | None = None) -> ChainImage:
    """Read every motor on PORT (:meth:`DeskLine.read_chain`)."""
    with DeskLine(port, bauds=bauds, ids=ids, progress=progress) as line:
        return line.read_chain(progress=progress)


def restore(image: ChainImage, port: str, *, bauds: Sequence[int] | None = None,
            save: bool = False, name: str = "the backup",
            progress: Progress | None = None) -> RestoreReport:
    """Write ``image`` to the motors on PORT (:meth:`DeskLine.restore`)."""
    with DeskLine(port, bauds=bauds, ids=image.ids or None, progress=progress) as line:
        return line.restore(image, save=save, name=name, progress=progress)


def factory_image(like: ChainImage, firmware: str | None = None) -> ChainImage:
    """The factory state of the motors of ``like`` (each of its firmware, or
    ``firmware`` for all): what a fresh virtual motor of that firmware answers, the
    same queries read (K values are table 6.1's defaults; the data where the manual is
    silent are docs/fidelity.md's).  Only the data names ``like`` holds are kept (a C
    type has no N and R, 6.6)."""
    fresh: dict[str, MotorImage] = {}
    motors: list[MotorImage] = []
    for motor in like.motors:
        name = firmware or motor.firmware
        if name not in fresh:
            fresh[name] = _virtual_motor(name)
        base = fresh[name].relabel(motor.motor)
        data = {k: v for k, v in base.data.items() if k in motor.data or not motor.data}
        motors.append(MotorImage(base.motor, base.title, base.params, data, base.banks))
    return ChainImage(tuple(motors), "factory")


def _virtual_motor(firmware: str) -> MotorImage:
    port = open_port(f"coolmuscle://?firmware={firmware}&mode=fast")
    try:
        session = Session(timeout=listing_timeout(38400))
        image: MotorImage = SyncDriver(port, session).run(read_motor(session, 1))
        return image
    finally:
        port.close()

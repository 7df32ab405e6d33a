"""The live twin: a virtual motor beside the real one, sent every line the real one gets.

``coolmuscle web PORT --twin [machine.toml]`` (docs/real-motor.md "The live twin beside
it").  At the start the real chain is read whole, as a backup reads it (the desk's
:func:`~coolmuscle.tools.desk.reading.read_motor`: K parameters, data registers, banks),
and written into an in-process :class:`~coolmuscle.chain.daisy.Chain` of the same size
and firmware on the machine file's load, as a restore writes it
(:func:`~coolmuscle.tools.desk.restorer.run_restore`, every part read back).  The twin
then stands where the real motors stand: moved in virtual time to each real position
(``P.n=`` and ``^.n``, the direct-mode data put back after), freed where the real one is
free, and its driver's idle temperature is the real one's unless the machine file sets
one.  From then on it runs paced to the wall clock and:

* **every line written to the real line** (the user's console, buttons, K writes, bank
  uploads, restores, and the poll's queries) is fed to the twin's host line when its
  CR reaches the real motor (the line's wire time at the K20 rate after it was written),
  so the twin answers the same session at the same instants;
* **the session is a capture**: both directions with their instants, written as
  ``coolmuscle capture`` writes one (:class:`~coolmuscle.tools.script.transcript.
  SessionWriter`, :func:`~coolmuscle.tools.capture.recording.header_lines`), for
  ``coolmuscle compare`` and ``fit`` (docs/twin.md);
* **the comparison is compare's own**: every :data:`CHECK_PERIOD` seconds the lines of
  the last stretch, real and virtual, go through
  :func:`coolmuscle.tools.twin.compare.compare` with its tolerances (the twin's output
  is the replay: each line with its instant and, for a polled value, the exact value
  before rounding; its trace recorder gives the tolerance bands), and each difference
  beyond them is shown on the page;
* after each poll round the twin's position, speed and torque ride in the page's
  snapshot rows beside the real ones (:data:`TWIN_FIELDS`): the charts overlay them.
"""

from __future__ import annotations

import asyncio
import bisect
import collections
import contextlib
import dataclasses
import datetime
import json
import logging
import re
import time
from pathlib import Path
from typing import Any

from ...chain.daisy import Chain
from ...chain.machine import AxisSpec, Machine, load_machine
from ...client.ops import Op, query
from ...client.replies import parse_int_reply
from ...frontends.transports.base import Port
from ...motor.status import ALARM_BITS, Ux
from ...sim.kernel import NS_PER_S
from ...sim.realtime import RealtimeDriver
from ..capture.recording import header_lines
from ..capture.settings import LineSettings
from ..desk.errors import DeskError
from ..desk.image import DIRECT_KINDS, ChainImage, MotorImage
from ..desk.reading import read_motor
from ..desk.restorer import plan_restore, run_restore
from ..script.runner import Script
from ..script.transcript import SessionWriter
from ..trace.recorder import TraceRecorder, record
from ..twin.compare import KIND_NAMES, Tolerance, Verdict, compare
from ..twin.replay import Replay, exact_value, speed_unit_pps
from ..twin.session import Line, Session, parse_poll
from .deskpage import EchoLink
from .hub import Hub
from .line import BITS_PER_BYTE, LineDevice

__all__ = ["TWIN_FIELDS", "LiveTwin", "Judged", "describe"]

log = logging.getLogger(__name__)

#: The twin's columns in a snapshot row, after the real ones.
TWIN_FIELDS = ("twin_position", "twin_speed", "twin_torque")
#: Seconds between two comparisons of what came since.
CHECK_PERIOD = 0.5
#: A line is judged once it is this old (s): its partner has come by then (a reply
#: within compare's timing tolerance, 20 ms and the wire time, with room to spare).
SETTLE = 0.5
#: Seconds before the stretch judged whose lines take part in the pairing again (the
#: last command before them comes too, for its lag: compare's ``_command_lags``).
LOOKBACK = 1.0
#: Differences kept for the page (the newest).
KEEP = 20
#: Virtual seconds the twin may take to reach the real motor's position.
PLACE_TIMEOUT = 3600.0
_LINE_END = re.compile(rb"\r\n|\r|\n")
#: Line numbers of the session: the lines sent this far apart, the lines received
#: after each numbered between (compare orders them by number, :meth:`_line_no`).
LINE_GAP = 1000
_CAPTURE_LINE = re.compile(r"^line \d+ \(([0-9.]+ s)\)")


@dataclasses.dataclass
class Judged:
    """What the comparison found so far."""

    compared: int = 0
    differences: int = 0
    recent: list[str] = dataclasses.field(default_factory=list)
    counts: dict[str, int] = dataclasses.field(
        default_factory=lambda: {kind: 0 for kind in KIND_NAMES})


class LiveTwin:
    """A virtual chain that shadows a real line (module docstring)."""

    def __init__(self, machine: Path | None = None,
                 tolerance: Tolerance | None = None) -> None:
        self.machine_path = machine.resolve() if machine is not None else None
        self.tolerance = tolerance or Tolerance()
        self.chain: Chain | None = None
        self.port: Port | None = None
        self.driver: RealtimeDriver | None = None
        self.recorder: TraceRecorder | None = None
        self.notes: list[str] = []
        self.judged = Judged()
        self.sent: list[Line] = []
        self.received: list[Line] = []
        self.twin_lines: list[Line] = []
        self.twin_after: list[int] = []
        self.twin_exact: dict[int, float] = {}
        self._stamps: list[float] = []
        self._rx_times: list[float] = []
        self._rx_numbers: list[int] = []
        self._twin_times: list[float] = []
        self._wire_free = 0.0
        self._echoes: collections.deque[int] = collections.deque(maxlen=64)
        self._owner = -1
        self._owner_count = 0
        self._fed = -1
        self._line: LineDevice | None = None
        self._hub: Hub | None = None
        self._rows: dict[int, list[Any]] = {}
        self._rx_buffer = bytearray()
        self._twin_buffer = bytearray()
        self._capture: list[str] = []
        self._writer = SessionWriter(self._capture.append, stamps=True)
        self._header: list[str] = []
        self._start = 0.0
        self._origin_ns = 0
        self._judged_to = 0.0
        self._tasks: list[asyncio.Task[None]] = []
        self._byte_s = 0.0

    # -- before the session ------------------------------------------------------
    async def prepare(self, line: LineDevice) -> None:
        """Read the real chain and build the twin from it (module docstring)."""
        ids = line.motor_ids
        image = await line.run(_read_chain(line, ids))
        placed: dict[int, tuple[int, int, int]] = {}
        for motor in ids:
            position = await line.run(_ask(line, motor, 96, "Px"))
            status = await line.run(_ask(line, motor, 99, "Ux"))
            temperature = await line.run(_ask(line, motor, 71, "Temp"))
            placed[motor] = (position, status, temperature)
        machine = load_machine(self.machine_path) if self.machine_path else None
        machine = _with_idle(machine, {m: t for m, (_p, _s, t) in placed.items()})
        kinds = [line.firmware_of(m) for m in range(1, max(ids) + 1)]
        firmware = ",".join(kinds) if len(set(kinds)) > 1 else kinds[0]
        chain = Chain(None, max(ids), firmware=firmware, machine=machine)
        try:
            self._copy(chain, image)
            for motor, (position, status, _t) in placed.items():
                self._place(chain, image.motor(motor), position, status)
        except BaseException:
            chain.close()
            raise
        self.chain = chain
        self._line = line
        first = image.motors[0]
        k23 = first.params.get(23)
        echo = None if k23 is None else not k23 & 8
        settings = LineSettings(baud=line.line_baud, parity="none", echo=echo,
                                k20=first.params.get(20), k23=k23, firmware=first.firmware)
        started = datetime.datetime.now(datetime.UTC)
        self._header = header_lines(line.url, settings, started, motors=max(ids),
                                    machine=str(self.machine_path) if self.machine_path
                                    else None)

    @staticmethod
    def _copy(chain: Chain, image: ChainImage) -> None:
        """The image written into the twin as a restore writes it, every part read back."""
        link = EchoLink(chain, image.ids[0], lambda entry: None)
        live = ChainImage(tuple(link.run(read_motor(link.session, m)) for m in image.ids),
                          "the twin")
        report = run_restore(link.run, link.session, plan_restore(image, live), image)
        if not report.ok:
            raise DeskError("the twin cannot hold what the real motors hold: "
                            + "; ".join(report.lines()[-2:]))

    def _place(self, chain: Chain, image: MotorImage, position: int, status: int) -> None:
        """The twin to the real motor's position (a move in virtual time), its direct
        data put back; free where the real one is."""
        n = image.motor
        if position != 0:
            speed = image.data.get("S", "0")
            chain.execute(f"S.{n}={speed if speed.lstrip('-') not in ('', '0') else 10}",
                          motor=n)
            chain.execute(f"P.{n}={position}", motor=n)
            chain.execute(f"^.{n}", motor=n)
            end = chain.kernel.now + int(PLACE_TIMEOUT * NS_PER_S)
            while chain.kernel.now < end:
                if chain.snapshot(n).status & (Ux.IN_POSITION | ALARM_BITS):
                    break
                chain.kernel.run(until=chain.kernel.now + NS_PER_S // 10)
            if chain.snapshot(n).position != position:
                self.notes.append(f"ID{n}: the twin did not reach the real position "
                                  f"Px={position} (it stands at "
                                  f"{chain.snapshot(n).position})")
            for kind in DIRECT_KINDS:
                if kind in image.data:
                    chain.execute(f"{kind}.{n}={image.data[kind]}", motor=n)
        if status & Ux.MOTOR_FREE:
            chain.execute(f").{n}", motor=n)
        if status & ALARM_BITS:
            self.notes.append(f"ID{n} has an alarm (Ux={status}); the twin has none")

    # -- the session --------------------------------------------------------------------
    def attach(self, line: LineDevice, hub: Hub) -> None:
        """Start the twin's clock and the session (call in the page's loop)."""
        assert self.chain is not None
        self._hub = hub
        self.driver = RealtimeDriver(self.chain.kernel)
        self.port = Port(self.chain, self.driver)
        loop = asyncio.get_running_loop()
        self._tasks.append(loop.create_task(self.driver.run(), name="coolmuscle-twin"))
        self.recorder = self.port.call(record, self.chain)
        self._start = time.monotonic()
        self._origin_ns = self.port.call(lambda: self.chain.kernel.now
                                         if self.chain is not None else 0)
        self._byte_s = BITS_PER_BYTE / line.line_baud
        self.port.add_listener(self._twin_bytes)
        line.taps.append(self._real_bytes)
        line.on_round.append(self._sample)
        self._tasks.append(loop.create_task(self._checker(), name="coolmuscle-twin-check"))
        for note in self.notes:
            hub.add_log([line.kernel.now, "note", f"twin: {note}", 0, "web"])

    async def close(self) -> None:
        for task in self._tasks:
            task.cancel()
        if self.driver is not None:
            self.driver.stop()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        self._tasks.clear()
        if self.chain is not None:
            self.chain.close()

    def _now(self) -> float:
        return time.monotonic() - self._start

    def _real_bytes(self, direction: str, data: bytes) -> None:
        now = self._now()
        if direction == ">":
            self._sent_bytes(now, data)
        else:
            read = self._line.read_at if self._line is not None else None
            if read is not None:             # when the reader thread read them
                now = min(now, read - self._start)
            self._writer.feed(now, "<", data)
            self._rx_buffer += data
            for piece in _lines(self._rx_buffer):
                number = self._line_no(now, piece)
                self.received.append(Line(now, "<", piece, number))
                self._rx_times.append(now)
                self._rx_numbers.append(number)

    def _line_no(self, at: float, data: bytes) -> int:
        """Where a line received at ``at`` stands among the lines sent (compare pairs a
        reply with the line sent before it, and measures a command's lag by the first
        line back after it): after its own line when it is that line's echo (ch. 3 K23
        8 off), else after the last line whose CR had reached the motor; never before
        the line received before it."""
        text = data.rstrip(b"\r\n")
        owner = None
        for pos, index in enumerate(self._echoes):
            if self.sent[index].data.rstrip(b"\r\n") == text:
                owner = index
                for _ in range(pos + 1):         # older lines whose echo never came
                    self._echoes.popleft()
                break
        if owner is None:
            arrived = bisect.bisect_right(self._stamps, at - self._byte_s) - 1
            owner = arrived
        owner = max(owner, self._owner)
        self._owner_count = self._owner_count + 1 if owner == self._owner else 1
        self._owner = owner
        return (owner + 1) * LINE_GAP + min(self._owner_count, LINE_GAP - 1)

    def _sent_bytes(self, now: float, data: bytes) -> None:
        """Each line's stamp: one byte before its CR reaches the motor; the twin gets
        it then (as the replay of a capture feeds it, docs/twin.md)."""
        loop = asyncio.get_running_loop()
        start = 0
        begins = max(now, self._wire_free)      # after what was written before it
        self._wire_free = begins + len(data) * self._byte_s
        for match in re.finditer(rb"\r", data):
            piece = data[start:match.end()]
            stamp = begins + (match.end() - 1) * self._byte_s
            self._writer.feed(stamp, ">", piece)
            index = len(self.sent)
            self.sent.append(Line(stamp, ">", piece, (index + 1) * LINE_GAP))
            self._stamps.append(stamp)
            self._echoes.append(index)
            loop.call_later(max(0.0, stamp + self._byte_s - self._now()), self._feed,
                            index, piece)
            start = match.end()
        if start < len(data):                    # a line not ended: it goes on alone
            self._writer.feed(now, ">", data[start:])
            loop.call_later(len(data) * self._byte_s, self._feed, -1, data[start:])

    def _feed(self, index: int, piece: bytes) -> None:
        if self.port is None:
            return
        if index >= 0:
            self._fed = index
        try:
            self.port.feed(piece)
        except Exception:
            log.exception("twin: feeding %r failed", piece[:40])

    def _twin_bytes(self, data: bytes) -> None:
        chain = self.chain
        if chain is None:
            return
        at = (chain.kernel.now - self._origin_ns) / NS_PER_S
        self._twin_buffer += data
        for piece in _lines(self._twin_buffer):
            index = len(self.twin_lines)
            self.twin_lines.append(Line(at, "<", piece, 0))
            self._twin_times.append(at)
            self.twin_after.append(self._fed)
            found = parse_poll(self.twin_lines[index].text)
            if found is not None and found[1] in chain.motor_ids:
                self.twin_exact[index] = exact_value(chain, found[1], found[0])

    # -- what the page shows -----------------------------------------------------------
    def _sample(self) -> None:
        """After a poll round: the twin's values beside the real ones."""
        if self.port is None or self.chain is None:
            return
        chain = self.chain
        for motor in chain.motor_ids:
            snap = self.port.call(chain.snapshot, motor)
            self._rows[motor] = [snap.position, snap.speed, snap.torque]

    def values(self, motor: int) -> list[Any]:
        return self._rows.get(motor, [None, None, None])

    def info(self) -> dict[str, Any]:
        j = self.judged
        return {"machine": str(self.machine_path) if self.machine_path else "the default "
                "machine", "compared": j.compared, "differences": j.differences,
                "recent": list(j.recent), "tolerance": self.tolerance.describe(
                    self._line.line_baud if self._line else None, BITS_PER_BYTE)}

    def capture_text(self) -> str:
        """The session so far as a capture file (docs/twin.md "The capture file")."""
        w = self._writer
        return "\n".join(self._header) + "\n" + "".join(self._capture) + (
            f"# end: sent={w.sent_lines} received={w.received_lines} bytes_to_motor="
            f"{w.bytes_sent} bytes_from_motor={w.bytes_received} stopped=saved-from-the-page\n")

    # -- the comparison -------------------------------------------------------------------
    async def _checker(self) -> None:
        while True:
            await asyncio.sleep(CHECK_PERIOD)
            try:
                new = self.check()
            except Exception:
                log.exception("twin: the comparison failed")
                continue
            if new is not None and self._hub is not None:
                self._hub.broadcast(json.dumps({"t": "twin", **self.info()},
                                               separators=(",", ":")))
                if new:                      # one line a stretch in the log
                    more = f" (and {len(new) - 1} more)" if len(new) > 1 else ""
                    self._hub.add_log([self._line.kernel.now if self._line else 0, "note",
                                       f"twin: {describe(new[0])}{more}", 0, "web"])

    def _last_command(self, before: int) -> int | None:
        """The last line sent before index ``before`` that is not a ``?`` query."""
        for index in range(before - 1, max(before - 2000, 0) - 1, -1):
            if not _is_query(self.sent[index]):
                return index
        return None

    def _first_back(self, command: int) -> Line | None:
        """The first line received after the line sent at ``command``."""
        at = bisect.bisect_right(self._rx_numbers, self.sent[command].line_no)
        return self.received[at] if at < len(self.received) else None

    def check(self, until: float | None = None) -> list[Verdict] | None:
        """Judge the lines of the stretch not judged yet (up to ``until`` s of the
        session, default :data:`SETTLE` s ago); the new differences, or ``None`` when
        nothing was judged."""
        end = (self._now() - SETTLE) if until is None else until
        start = self._judged_to
        if end <= start or self.port is None:
            return None
        lo = start - LOOKBACK
        first_sent = bisect.bisect_left(self._stamps, lo)
        sent = self.sent[first_sent:]
        real = self.received[bisect.bisect_left(self._rx_times, lo):]
        command = self._last_command(first_sent)
        shift = first_sent
        if command is not None:              # the command the polls since may lag on
            sent = [self.sent[command]] + sent
            shift -= 1
            back = self._first_back(command)
            if back is not None and (not real or back.line_no < real[0].line_no):
                real = [back] + real
        twin_from = bisect.bisect_left(self._twin_times, lo)
        twin = self.twin_lines[twin_from:]
        after = [a - shift if a >= first_sent else (0 if command is not None
                                                    and a >= command else -1)
                 for a in self.twin_after[twin_from:]]
        exact = {i - twin_from: self.twin_exact[i]
                 for i in range(twin_from, len(self.twin_lines)) if i in self.twin_exact}
        session = Session("live", {"baud": str(self._line.line_baud if self._line else 0),
                                   "parity": "none"}, Script(()), sent, real)
        chain = self.chain
        assert chain is not None
        replay = Replay(twin, after, exact, self._origin_ns, None, self.recorder,
                        {m: speed_unit_pps(chain, m) for m in chain.motor_ids})
        report = self.port.call(compare, session, replay, self.tolerance)
        self._judged_to = end
        new: list[Verdict] = []
        j = self.judged
        for verdict in report.verdicts:
            at = verdict.real.time if verdict.real is not None else \
                verdict.virtual.time if verdict.virtual is not None else 0.0
            if not start <= at < end:
                continue
            j.compared += 1
            j.counts[verdict.kind] += 1
            if verdict.differs:
                j.differences += 1
                new.append(verdict)
        j.recent = (j.recent + [describe(v) for v in new])[-KEEP:]
        return new


def describe(verdict: Verdict) -> str:
    """compare's line for a verdict, the session's second in front (a live session has
    no capture file whose lines it could name)."""
    return _CAPTURE_LINE.sub(r"\1", verdict.describe())


def _is_query(line: Line) -> bool:
    return line.text.lstrip().startswith("?")


def _lines(buffer: bytearray) -> list[bytes]:
    """The complete lines at the start of ``buffer`` (taken out), with their line ends;
    a CR at the very end waits for the LF that may follow (K70=1: CR LF)."""
    out: list[bytes] = []
    while (end := _LINE_END.search(buffer)) is not None:
        if end.group() == b"\r" and end.end() == len(buffer):
            break
        data = bytes(buffer[:end.end()])
        del buffer[:end.end()]
        if data.strip(b"\r\n"):
            out.append(data)
    return out


def _read_chain(line: LineDevice, ids: tuple[int, ...]) -> Op[ChainImage]:
    """Every motor of ``ids`` read whole."""
    motors: list[MotorImage] = []
    for motor in ids:
        motors.append((yield from read_motor(line.session, motor)))
    return ChainImage(tuple(motors), line.url, line.baud)


def _ask(line: LineDevice, motor: int, number: int, name: str) -> Op[int]:
    reply = yield from query(line.session, motor, f"?{number}.{motor}", name)
    return parse_int_reply(reply, name, motor)


def _with_idle(machine: Machine | None, temperatures: dict[int, int]) -> Machine:
    """``machine`` with each motor's idle driver temperature the real one's, where the
    file gives none (``[axis.thermal] idle``, docs/machine-file.md)."""
    axes = {a.motor: a for a in (machine.axes if machine else [])}
    out: list[AxisSpec] = []
    for motor, temperature in sorted(temperatures.items()):
        spec = axes.pop(motor, None) or AxisSpec(motor=motor)
        if "idle" not in spec.thermal:
            spec = dataclasses.replace(spec, thermal={**spec.thermal,
                                                      "idle": float(temperature)})
        out.append(spec)
    out += axes.values()
    return Machine(out, machine.source if machine else "<the real motors>")


"""Raw-socket transport: EtherCAT frames (EtherType 0x88A4) on an AF_PACKET socket.

:class:`FrameThread` answers every frame in its own thread (like an ESC answers in
hardware), so the motor model never delays an answer; the model side exchanges
process data through the slave stack's buffers.  :class:`EthercatTransport` is the
:class:`~coolmuscle.transports.base.Transport` that ``coolmuscle sim --ethercat``
starts in the service loop: it owns the frame thread and starts the bridge's 1 ms
cycle (manual 6.3), kernel events in the model's thread.

Needs root or CAP_NET_RAW.  The loopback interface is refused: a frame sent on
``lo`` comes back to the sender unchanged, so a master there would read its own
frames as answers (and the slave its own answers as requests).
"""

from __future__ import annotations

import gc
import logging
import os
import socket
import struct
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from ...errors import TransportError
from ..transports.base import Port, Transport
from .engine.esc import ETHERTYPE_ECAT, Esc

if TYPE_CHECKING:
    from ...sim.realtime import RealtimeClock
    from .bridge.app import BridgeApp

log = logging.getLogger(__name__)

PACKET_OUTGOING = 4
FRAME_PRIORITY = 40
MODEL_PRIORITY = 20
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)
#: Python switches threads every 5 ms by default: far longer than a 1 ms cycle.
SWITCH_INTERVAL = 0.0002


def cycle_collector() -> Callable[[], None]:
    """The cyclic garbage collector while the bridge cycles (``sim --ethercat``); returns
    what undoes it.

    The start-up objects leave it (``gc.freeze``: no collection walks them again, shorter
    GIL pauses) and automatic collection stays on at the interpreter's thresholds.
    Chosen by measurement (bench/bench_ethercat_csp.py, which runs this very setting;
    docs/performance.md): a csp cycle leaves nothing behind for the collector (the
    motion caches keep no per-cycle entry), so with the compiled modules not one
    collection starts in 16,000 cycles, and a raised threshold or collecting between
    cycles has nothing to change (a threshold raised far would only make each collection
    that other traffic, the CML port or Modbus, still causes longer)."""
    gc.freeze()
    return gc.unfreeze


def check_interface(iface: str) -> None:
    """Refuse a name that cannot carry the bridge (loopback, missing interface)."""
    if not iface:
        raise TransportError("--ethercat needs an interface name (there is no default)")
    if iface == "lo" or iface.startswith("lo:"):
        raise TransportError("refusing the loopback interface 'lo': it reflects every frame "
                             "to its sender, so a master would read its own frames; use a "
                             "veth pair (coolmuscle ethercat lab up) or a real NIC")
    try:
        socket.if_nametoindex(iface)
    except OSError:
        raise TransportError(f"no network interface {iface!r}") from None


def open_socket(iface: str) -> socket.socket:
    """An AF_PACKET socket bound to ``iface`` for EtherType 0x88A4."""
    try:
        sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETHERTYPE_ECAT))
    except PermissionError:
        raise TransportError("raw sockets need root or CAP_NET_RAW "
                             "(sudo setcap cap_net_raw+ep on the python binary)") from None
    except OSError as exc:
        raise TransportError(f"cannot open an AF_PACKET socket: {exc}") from None
    try:
        sock.bind((iface, ETHERTYPE_ECAT))
    except OSError as exc:
        sock.close()
        raise TransportError(f"cannot bind to {iface!r}: {exc.strerror or exc}") from None
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
    sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    return sock


def _kernel_time(ancdata: list[tuple[int, int, bytes]]) -> int:
    """The kernel's receive time stamp (ns, CLOCK_REALTIME) of a frame, 0 if none."""
    for level, kind, data in ancdata:
        if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(data) >= 16:
            sec: int
            nsec: int
            sec, nsec = struct.unpack_from("@qq", data)
            return sec * 1_000_000_000 + nsec
    return 0


class FrameThread:
    """Receive, process and send back EtherCAT frames for one ESC, in a thread."""

    def __init__(self, esc: Esc, iface: str, *, keep: int = 100_000,
                 priority: int = FRAME_PRIORITY) -> None:
        self.esc = esc
        self.priority = priority
        self.realtime = False
        self.iface = iface
        self.sock = open_socket(iface)
        self.sock.settimeout(0.001)
        #: Kernel receive time stamp to answer sent, ns (includes waiting for the GIL).
        self.turnaround_ns: deque[int] = deque(maxlen=keep)
        self.errors = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"ethercat-{iface}", daemon=True)
        self._old_switch = sys.getswitchinterval()

    def start(self) -> None:
        sys.setswitchinterval(min(self._old_switch, SWITCH_INTERVAL))
        self._thread.start()

    def _realtime(self) -> None:
        """Run this thread under SCHED_FIFO when allowed (root): a real ESC never waits."""
        if self.priority <= 0 or not hasattr(os, "sched_setscheduler"):
            return
        try:
            os.sched_setscheduler(threading.get_native_id(), os.SCHED_FIFO,
                                  os.sched_param(self.priority))
            self.realtime = True
        except (OSError, PermissionError):
            log.info("frame thread stays at normal priority (no CAP_SYS_NICE)")

    def _run(self) -> None:
        self._realtime()
        sock, esc = self.sock, self.esc
        buf = bytearray(2048)
        view = memoryview(buf)
        clock, wall = time.monotonic_ns, time.time_ns
        anc = socket.CMSG_SPACE(16)
        while not self._stop.is_set():
            try:
                n, ancdata, _flags, addr = sock.recvmsg_into([buf], anc)
            except TimeoutError:
                esc.tick(clock())
                continue
            except OSError:
                if self._stop.is_set():
                    break
                self.errors += 1
                continue
            if addr[2] == PACKET_OUTGOING:
                continue
            try:
                out = esc.process(view[:n], clock())
            except Exception:      # a bug must not stop the slave: the frame is lost
                self.errors += 1
                log.exception("ESC failed on a frame")
                continue
            if out is None:
                continue
            try:
                sock.send(out)
            except OSError:
                self.errors += 1
            arrived = _kernel_time(ancdata)
            if arrived:
                self.turnaround_ns.append(wall() - arrived)

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(2.0)
        self.sock.close()
        sys.setswitchinterval(self._old_switch)


class CycleLateness:
    """How late the bridge's cycles start on the wall clock (the model's thread).

    A cycle is late when it starts more than ``cycle_s`` of wall time after the wall
    instant of its virtual instant (the paced kernel fell behind, or the event loop
    woke late)."""

    def __init__(self, clock: RealtimeClock, cycle_s: float) -> None:
        self.clock = clock
        self.cycle_s = cycle_s
        self.cycles = 0
        self.late = 0
        self.worst = 0.0

    def note(self, virtual_ns: int) -> None:
        """A cycle due at kernel time ``virtual_ns`` starts now."""
        late = self.clock.lateness(virtual_ns)
        self.cycles += 1
        self.worst = max(self.worst, late)
        if late > self.cycle_s:
            self.late += 1


class EthercatTransport(Transport):
    """``sim --ethercat IFACE``: the bridge as an EtherCAT slave on a raw interface."""

    name = "ethercat"

    def __init__(self, where: str = "", bridge: str = "EB02", cycle_s: float = 0.001) -> None:
        super().__init__()
        check_interface(where)
        self.iface = where
        self.bridge = bridge
        self.cycle_s = cycle_s
        self.app: BridgeApp | None = None
        self.frames: FrameThread | None = None
        self.lateness: CycleLateness | None = None
        self.realtime_model = True
        self._old_policy: tuple[int, os.sched_param] | None = None
        self._collector: Callable[[], None] = lambda: None   # undoes cycle_collector

    async def start(self, port: Port) -> None:
        from .bridge.app import BridgeApp
        self.port = port
        if port.device is None:
            raise TransportError("ethercat: no device behind this port")
        self.app = BridgeApp(port.device, self.bridge)
        self.frames = FrameThread(self.app.stack.esc, self.iface)
        self._collector = cycle_collector()
        self._model_realtime(True)
        self.frames.start()
        # The bridge's 1 ms cycle (6.3) runs in the model's thread as kernel events on
        # an exact grid (BridgeApp.start_cycles): the paced kernel reaches them with
        # the wall clock.  The master's frames come in wall time, so under a time scale
        # the cycle stays 1 ms of wall time (scale x 1 ms of the motors' time).
        scale = 1.0
        if port.driver is not None:
            scale = port.driver.clock.scale
            self.lateness = CycleLateness(port.driver.clock, self.cycle_s)
            port.driver.precise = True      # the selector's 1 ms granularity: see PreciseWaker
        port.call(self.app.start_cycles, max(1, round(self.cycle_s * scale * 1e9)),
                  self._cycle_starts)

    def _cycle_starts(self) -> None:
        if self.lateness is not None and self.app is not None and self.app.device is not None:
            self.lateness.note(self.app.device.kernel.now)

    @property
    def cycles(self) -> int:
        """Bridge cycles run."""
        return self.lateness.cycles if self.lateness is not None else 0

    @property
    def late_cycles(self) -> int:
        """Cycles that started more than one cycle after their instant."""
        return self.lateness.late if self.lateness is not None else 0

    @property
    def max_late_s(self) -> float:
        """The latest a cycle started after its instant (wall seconds)."""
        return self.lateness.worst if self.lateness is not None else 0.0

    def _model_realtime(self, on: bool) -> None:
        """The model's thread under SCHED_FIFO below the frame thread (when allowed).

        The frame thread needs the GIL; a model thread preempted by another program
        while it holds the GIL would delay every answer.  At a real-time priority the
        model thread runs until it releases the GIL (at most the switch interval).
        """
        if not self.realtime_model or not hasattr(os, "sched_setscheduler"):
            return
        try:
            if on:
                self._old_policy = os.sched_getscheduler(0), os.sched_getparam(0)
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(MODEL_PRIORITY))
            elif self._old_policy is not None:
                os.sched_setscheduler(0, self._old_policy[0], self._old_policy[1])
                self._old_policy = None
        except (OSError, PermissionError):
            log.info("model thread stays at normal priority (no CAP_SYS_NICE)")

    def describe(self) -> str:
        return f"ethercat: {self.iface} ({self.bridge}, EtherCAT slave, EtherType 0x88A4)"

    def info(self) -> dict[str, Any]:
        return {"iface": self.iface, "bridge": self.bridge}

    async def close(self) -> None:
        if self.app is not None and self.port is not None:
            self.port.call(self.app.stop_cycles)
        if self.frames is not None:
            self.frames.close()
            self.frames = None
            self._model_realtime(False)
            self._collector()

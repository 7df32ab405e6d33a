"""A wire-fault storm on a served chain, for the test and the benchmark alike (plain
Python, no pytest: bench/bench_wirefaults.py imports it with ``tests/`` on its path).

:func:`storm` serves a chain of three motors (CM2, CM2, CM1) with its store on the
motor's TCP host line, Modbus TCP and the CM1 EtherNet/IP module, and for ``seconds``:

* peers keep talking: the host library over TCP (registers written and read back,
  positions), pymodbus over Modbus TCP (retries on), pycomm3 reading the CM1's input
  assembly over a class 3 connection (docs/wire-faults.md: each sees only its typed
  errors: ``CoolMuscleTimeout``, ``ProtocolError``, a Modbus error response, a CIP
  status);
* faults rain on every door from the vocabulary, each with a random kind, parameters
  and a short window (a seeded ``random.Random`` of this driver: the model's own
  choices are the faults' generators), and motor 2 is saved (``$``, through the device
  API) then powered off and on again, over and over: after every power-up its
  registers must be what was saved (only cycles whose power-up was checked are
  counted; a motor still off after :data:`POWER_UP_WAIT_S` is reported, not skipped);
* it counts what must stay zero: log records with a traceback or at ERROR from
  coolmuscle, front-end failures (``Port.errors``), unexpected exceptions in a peer,
  saved data that did not come back; and samples the process's resident memory.

At the end the store is opened again by a new chain: it must hold the last save.
"""

from __future__ import annotations

import logging
import os
import random
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from coolmuscle import connect
from coolmuscle.chain.daisy import Chain
from coolmuscle.errors import CoolMuscleError
from coolmuscle.frontends.enip.server import EnipTransport
from coolmuscle.frontends.transports.modbus_tcp import ModbusTcpTransport
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.frontends.transports.tcp import TcpTransport

FIRMWARE = "cm2,cm2,cm1"
#: Faults the storm draws: (door, kind, parameters).
FAULTS: list[tuple[str, str, dict[str, Any]]] = [
    ("host-line", "drop", {}), ("host-line", "garble", {}),
    ("host-line", "delay", {"ms": 150}), ("host-line", "split", {"pieces": 3}),
    ("host-line", "duplicate", {}), ("host-line", "latency", {}),
    ("host-line", "dead", {}), ("host-line", "drop", {"echo": True}),
    ("modbus-tcp", "no_reply", {}), ("modbus-tcp", "late", {"ms": 400}),
    ("modbus-tcp", "exception", {"code": 6}), ("modbus-tcp", "wrong_unit", {}),
    ("enip", "forward_open_refused", {}), ("enip", "serial_link", {"state": "timeout"}),
    ("enip", "class1_loss", {"direction": "both"}),
    ("chain", "link_break", {"motor": 1}), ("chain", "power_off", {"motor": 3}),
]
LASTING = {"latency", "dead", "serial_link", "link_break", "power_off"}
#: How long a power cycle waits (wall clock) for its power-off window to end.
POWER_UP_WAIT_S = 5.0


def rss_mib() -> float:
    """The process's resident memory now (MiB; /proc/self/statm)."""
    with open("/proc/self/statm") as statm:
        pages = int(statm.read().split()[1])
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


@dataclass
class StormReport:
    seconds: float
    faults: int = 0
    power_cycles: int = 0
    exchanges: dict[str, int] = field(default_factory=dict)
    typed_errors: dict[str, int] = field(default_factory=dict)
    unexpected: list[str] = field(default_factory=list)
    tracebacks: list[str] = field(default_factory=list)
    lost_saves: list[str] = field(default_factory=list)
    #: Power cycles whose motor was still off when the bounded wait ended (unchecked).
    stuck_off: list[str] = field(default_factory=list)
    port_errors: int = 0
    rss: list[tuple[float, float]] = field(default_factory=list)

    @property
    def clean(self) -> bool:
        return not (self.unexpected or self.tracebacks or self.lost_saves or self.stuck_off
                    or self.port_errors)

    def problems(self) -> list[str]:
        """The first few of each kind of problem (for a failure message)."""
        return (self.unexpected[:5] + self.tracebacks[:5] + self.lost_saves[:5]
                + self.stuck_off[:5])

    def summary(self) -> str:
        rss = ", ".join(f"{t:.0f} s {m:.1f} MiB" for t, m in self.rss)
        return (f"{self.seconds:.0f} s: {self.faults} faults, {self.power_cycles} power "
                f"cycles, exchanges {self.exchanges}, typed errors {self.typed_errors}; "
                f"unexpected {len(self.unexpected)}, tracebacks {len(self.tracebacks)}, "
                f"lost saves {len(self.lost_saves)}, still off {len(self.stuck_off)}, "
                f"port errors {self.port_errors}; "
                f"RSS {rss}")


class _Errors(logging.Handler):
    """Every coolmuscle log record at ERROR or with a traceback."""

    def __init__(self, report: StormReport) -> None:
        super().__init__(logging.DEBUG)
        self.report = report

    def emit(self, record: logging.LogRecord) -> None:
        if record.exc_info or record.levelno >= logging.ERROR:
            self.report.tracebacks.append(f"{record.name}: {record.getMessage()}"[:300])


class _Peer(threading.Thread):
    """One peer's loop; typed errors counted, anything else is unexpected."""

    def __init__(self, name: str, report: StormReport, stop: threading.Event,
                 step: Callable[[], None], typed: tuple[type[BaseException], ...]) -> None:
        super().__init__(name=f"storm-{name}", daemon=True)
        self.label, self.report, self.stop, self.step, self.typed = name, report, stop, \
            step, typed

    def run(self) -> None:
        count = self.report.exchanges
        while not self.stop.is_set():
            try:
                self.step()
                count[self.label] = count.get(self.label, 0) + 1
            except self.typed as exc:
                key = f"{self.label}:{type(exc).__name__}"
                self.report.typed_errors[key] = self.report.typed_errors.get(key, 0) + 1
            except Exception as exc:           # noqa: BLE001 (counted: must stay 0)
                self.report.unexpected.append(f"{self.label}: {type(exc).__name__}: {exc}")
                time.sleep(0.05)


def _host_peer(port: int) -> tuple[Callable[[], None], Callable[[], None]]:
    m = connect(f"socket://127.0.0.1:{port}", timeout=0.3, firmware="cm2")
    rng = random.Random(1)

    def step() -> None:
        value = rng.randrange(-1000, 1000)
        m.write_register("P", 9, value)
        m.read_register("P", 9)
        m.get_position()
    return step, m.close


def _modbus_peer(port: int) -> tuple[Callable[[], None], Callable[[], None]]:
    from pymodbus.client import ModbusTcpClient
    client = ModbusTcpClient("127.0.0.1", port=port, timeout=0.3, retries=1)
    client.connect()

    def step() -> None:
        client.write_registers(218, [0, 7], device_id=1)           # P9 (K78=0)
        client.read_holding_registers(200, count=4, device_id=1)
    return step, client.close


def _enip_peer(port: int) -> tuple[Callable[[], None], Callable[[], None]]:
    from pycomm3 import CIPDriver
    driver = CIPDriver(f"127.0.0.1:{port}")
    driver.open()

    def step() -> None:
        driver.generic_message(service=0x0E, class_code=4, instance=0x65, attribute=3,
                               connected=True, route_path=False)
        time.sleep(0.01)
    return step, driver.close


def _rain(st: ServiceThread, report: StormReport, rng: random.Random) -> None:
    door, kind, params = rng.choice(FAULTS)
    schedule: dict[str, Any] = {"until": round(rng.uniform(0.05, 0.5), 3)}
    if kind not in LASTING:
        schedule[rng.choice(["every", "probability", "count"])] = \
            rng.choice([1, 2, 3]) if "probability" not in schedule else 0.5
        if "probability" in schedule:
            schedule["probability"], schedule["seed"] = 0.5, rng.randrange(1 << 32)
    params = dict(params)
    motor = params.pop("motor", None)
    st.call(lambda: st.chain.inject_wire_fault(door, kind, motor=motor, **schedule,
                                               **params))
    report.faults += 1


def _power_cycle(st: ServiceThread, report: StormReport, rng: random.Random,
                 saved: dict[int, int]) -> None:
    """``$.2`` with a new P5, P6 unsaved, off for a while, on: P5 back, P6 gone.

    Waits (at most :data:`POWER_UP_WAIT_S`) until the power-off window is over, then
    checks the registers in the same call on the service thread; only a checked cycle
    counts in ``power_cycles``, a motor still off is a ``stuck_off`` problem."""
    value = rng.randrange(-10**6, 10**6)

    def save() -> None:
        st.chain.set_register(2, "P", 5, value)
        st.chain.execute("$.2")
        st.chain.set_register(2, "P", 6, value + 1)       # never saved
    st.call(save)
    saved[2] = value
    st.call(lambda: st.chain.inject_wire_fault("chain", "power_off", motor=2, until=0.2))

    def powered_up() -> tuple[int | str, int | str] | None:
        if st.chain.wire_faults.lasting("chain", "power_off", 2) is not None:
            return None
        return st.chain.get_register(2, "P", 5), st.chain.get_register(2, "P", 6)
    deadline = time.monotonic() + POWER_UP_WAIT_S
    back = st.call(powered_up)
    while back is None and time.monotonic() < deadline:
        time.sleep(0.02)
        back = st.call(powered_up)
    if back is None:
        report.stuck_off.append(f"motor 2 still powered off {POWER_UP_WAIT_S:g} s after "
                                "a 0.2 s power_off window: its saved data unchecked")
        return
    if back != (value, 0):
        report.lost_saves.append(f"after power-up P5.2={back[0]} P6.2={back[1]}, "
                                 f"saved P5.2={value}")
    report.power_cycles += 1


def storm(seconds: float, *, samples: int = 3, seed: int = 7,
          on_sample: Callable[[float, float], None] | None = None) -> StormReport:
    """Run the storm for ``seconds`` of wall time (see the module docstring)."""
    report = StormReport(seconds)
    handler = _Errors(report)
    logging.getLogger("coolmuscle").addHandler(handler)
    quiet = {name: logging.getLogger(name).level for name in ("pymodbus", "pycomm3")}
    for name in quiet:                  # the peers' own reports of the faults
        logging.getLogger(name).setLevel(logging.CRITICAL)
    state = Path(tempfile.mkdtemp(prefix="storm-"))
    rng = random.Random(seed)
    saved: dict[int, int] = {}
    stop = threading.Event()
    st = ServiceThread(lambda: Chain(motors=3, firmware=FIRMWARE, state_dir=state),
                       lambda: [TcpTransport(port=0), ModbusTcpTransport(port=0),
                                EnipTransport(port=0, io_port=0, motor=3)]).start()
    closers: list[Callable[[], None]] = []
    try:
        peers = []
        for name, make, port, typed in [
                ("host", _host_peer, st.transports[0].info()["port"], (CoolMuscleError,)),
                ("modbus", _modbus_peer, st.transports[1].info()["port"], _modbus_errors()),
                ("enip", _enip_peer, st.transports[2].info()["port"], _cip_errors())]:
            step, close = make(port)
            closers.append(close)
            peers.append(_Peer(name, report, stop, step, typed))
        for peer in peers:
            peer.start()
        start = time.monotonic()
        marks = [start + seconds * (i + 1) / samples for i in range(samples)]
        report.rss.append((0.0, rss_mib()))
        while time.monotonic() - start < seconds:
            for _ in range(5):
                _rain(st, report, rng)
                time.sleep(0.02)
            _power_cycle(st, report, rng, saved)
            if marks and time.monotonic() >= marks[0]:
                marks.pop(0)
                elapsed = time.monotonic() - start
                report.rss.append((elapsed, rss_mib()))
                if on_sample is not None:
                    on_sample(elapsed, report.rss[-1][1])
        stop.set()
        for peer in peers:
            peer.join(5)
        st.call(lambda: st.chain.clear_wire_faults())
        report.port_errors = st.service.port.errors
    finally:
        stop.set()
        for close in closers:
            try:
                close()
            except Exception:                    # noqa: BLE001 (a peer's own teardown)
                pass
        st.stop()
        logging.getLogger("coolmuscle").removeHandler(handler)
        for name, level in quiet.items():
            logging.getLogger(name).setLevel(level)
    _check_store(state, saved, report)
    return report


def _check_store(state: Path, saved: dict[int, int], report: StormReport) -> None:
    chain = Chain(motors=3, firmware=FIRMWARE, state_dir=state)
    try:
        for motor, value in saved.items():
            found = chain.get_register(motor, "P", 5)
            if found != value:
                report.lost_saves.append(f"store: P5.{motor}={found}, saved {value}")
    finally:
        chain.close()


def _modbus_errors() -> tuple[type[BaseException], ...]:
    from pymodbus.exceptions import ModbusException
    return (ModbusException,)


def _cip_errors() -> tuple[type[BaseException], ...]:
    from pycomm3.exceptions import PycommError
    return (PycommError,)

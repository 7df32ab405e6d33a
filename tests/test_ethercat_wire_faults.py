"""The ``ethercat`` door's wire faults, sans IO: a segment of three bridges (one kernel,
a chain of four motors each) driven frame by frame by a small master in virtual time.

ETG.1000.4 table 12 (the working counter), the mailbox repeat request (SM1 activate bit
1, PDI control bit 1); manual 5.2.2 (AL status code 001Bh: SM watchdog), 6.3 (the 1 ms
cycle).  docs/wire-faults.md "ethercat".  The same faults under pysoem on a veth pair:
tests/test_ethercat_wire_faults_soem.py.
"""

from __future__ import annotations

import gc
import struct
import tracemalloc

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from coolmuscle.chain import Chain
from coolmuscle.chain.machine import MachineFileError, parse_machine
from coolmuscle.device.wire import describe, kinds
from coolmuscle.frontends.ethercat.bridge import identity as ident
from coolmuscle.frontends.ethercat.bridge.segment import BridgeSegment
from coolmuscle.frontends.ethercat.engine import esc as E
from coolmuscle.frontends.ethercat.engine import esm
from coolmuscle.sim.kernel import Kernel
from ethercat_support import datagrams, frame

MS = 1_000_000
CODES = ("EB02", "EB12", "EB01")
#: LRW of three bridges: each reads and writes (3 a bridge).
EXPECTED_WKC = 9


class Master:
    """A master of the segment in virtual time: stations 0x1001.., mailboxes, process
    data at 24 n (outputs) and 72 + 24 n (inputs), INIT to OP, one LRW a cycle."""

    def __init__(self, machine: str | None = None) -> None:
        self.kernel = Kernel()
        self.chains = [Chain(self.kernel, 4, firmware=",".join(ident.variant(c).firmware))
                       for c in CODES]
        if machine is not None:
            self.chains[0].load_machine(parse_machine(machine))
        self.seg = BridgeSegment(self.chains, CODES)
        self.seg.start_cycles()
        self.line = self.seg.line
        self.events: list[str] = []
        self.chains[0].subscribe(lambda e: self.events.append(f"{e.time} {e.text}")
                                 if e.kind == "wire" else None)

    def send(self, *grams: tuple[int, int, int, bytes]) -> list[tuple[int, int, bytes, int]] | None:
        out = self.line.process(frame(*grams), self.kernel.now)
        return None if out is None else datagrams(out)

    def one(self, cmd: int, adp: int, ado: int, data: bytes) -> tuple[bytes, int]:
        got = self.send((cmd, adp, ado, data))
        assert got is not None, "frame lost"
        return got[0][2], got[0][3]

    def ms(self, n: int = 1) -> None:
        self.kernel.run(until=self.kernel.now + n * MS)

    def to_op(self, stations: range | None = None) -> None:
        for n in stations if stations is not None else range(len(CODES)):
            self.configure(n)
        for state in (esm.PREOP, esm.SAFEOP, esm.OP):
            for n in stations if stations is not None else range(len(CODES)):
                self.one(E.FPWR, 0x1001 + n, E.REG_AL_CONTROL, struct.pack("<H", state))
            self.cycle()
        assert self.states() == [esm.OP] * len(CODES), [hex(s) for s in self.states()]

    def configure(self, n: int) -> None:
        station = 0x1001 + n
        self.one(E.APWR, -n & 0xFFFF, E.REG_STATION, struct.pack("<H", station))
        w = [(E.REG_AL_CONTROL, struct.pack("<H", esm.INIT | esm.ACK)),
             (E.REG_FMMU, bytes(16 * E.N_FMMU)), (E.REG_SM, bytes(8 * E.N_SM)),
             (E.REG_WD_DIVIDER, struct.pack("<H", 2498)), (E.REG_WD_SM, struct.pack("<H", 1000))]
        for s, (start, size, ctl) in enumerate(((ident.MBX_OUT_START, 128, 0x26),
                                                (ident.MBX_IN_START, 128, 0x22),
                                                (ident.PD_OUT_START, 24, 0x64),
                                                (ident.PD_IN_START, 24, 0x20))):
            w.append((E.REG_SM + 8 * s, struct.pack("<HHBBBB", start, size, ctl, 0, 1, 0)))
        for f, (logical, phys, kind) in enumerate(((24 * n, ident.PD_OUT_START, 2),
                                                   (72 + 24 * n, ident.PD_IN_START, 1))):
            w.append((E.REG_FMMU + 16 * f,
                      struct.pack("<IHBBHBBB3x", logical, 24, 0, 7, phys, 0, kind, 1)))
        for ado, data in w:
            assert self.one(E.FPWR, station, ado, data)[1] == 1, hex(ado)

    def states(self) -> list[int]:
        return [app.stack.esc.al_status for app in self.seg.apps]

    def cycle(self, outputs: bytes = bytes(72)) -> tuple[int, bytes] | None:
        """One LRW, then a millisecond: (working counter, inputs) or None (lost)."""
        got = self.send((E.LRW, 0, 0, outputs + bytes(72)))
        self.ms()
        return None if got is None else (got[0][3], got[0][2][72:])

    def run(self, cycles: int) -> list[tuple[int, bytes] | None]:
        return [self.cycle(struct.pack("<Hi", 0x0F if i > 20 else 0x06, 0) * 12)
                for i in range(cycles)]


# -- the vocabulary -----------------------------------------------------------------------
def test_the_vocabulary_has_the_ethercat_door_and_the_web_panel_lists_it():
    assert [k.name for k in kinds("ethercat")] == ["lost_frame", "wkc", "mailbox_lost",
                                                   "link_down", "late_cycle"]
    panel = describe()["ethercat"]
    assert [k["kind"] for k in panel["kinds"]] == [k.name for k in kinds("ethercat")]
    down = next(k for k in panel["kinds"] if k["kind"] == "link_down")
    assert down["lasting"] and "001B" in str(down["doc"]) and down["params"][0]["name"] == "bridge"


def test_a_machine_file_schedules_ethercat_faults_and_names_a_wrong_key():
    machine = parse_machine('[[wire.fault]]\ndoor = "ethercat"\nkind = "wkc"\nevery = 4\n'
                            'delta = 1\n')
    assert (machine.wire[0].kind, machine.wire[0].params) == ("wkc", {"delta": 1,
                                                                      "datagram": "process"})
    for text, said in (('kind = "link_down"\nevery = 2\n', "lasting"),
                       ('kind = "lost_frame"\nway = "sideways"\n', "way must be one of"),
                       ('kind = "late_cycle"\nms = -1\n', "ms must be"),
                       ('kind = "lost_frame"\nbridge = 65\n', "bridge must be 1..64")):
        with pytest.raises(MachineFileError, match=said):
            parse_machine(f'[[wire.fault]]\ndoor = "ethercat"\n{text}')


# -- fault free ----------------------------------------------------------------------------
def test_a_fault_free_run_passes_no_hook_and_is_unchanged():
    plain = Master()
    plain.to_op()
    first = plain.run(200)
    assert plain.line.tap is None and all(c is not None and c[0] == EXPECTED_WKC for c in first)
    # a fault whose window never comes: the same frames, bit for bit, and still no hook
    later = Master()
    later.chains[0].inject_wire_fault("ethercat", "lost_frame", at=3600.0)
    later.to_op()
    assert later.run(200) == first and later.line.tap is None and later.events == []


# -- each kind -------------------------------------------------------------------------------
def test_lost_frames_out_and_back():
    m = Master()
    m.to_op()
    m.chains[0].inject_wire_fault("ethercat", "lost_frame", bridge=2, every=3, count=2)
    escs = [app.stack.esc for app in m.seg.apps]
    before = [esc.frames for esc in escs]
    got = m.run(7)
    assert [g is None for g in got] == [False, False, True, False, False, True, False]
    assert m.seg.faults is not None and m.seg.faults.lost == 2
    # lost on its way out at bridge 2: bridge 1 had processed it, bridges 2-3 never saw it
    assert [esc.frames - n for esc, n in zip(escs, before)] == [7, 5, 5]
    m.chains[0].inject_wire_fault("ethercat", "lost_frame", way="back", count=1)
    m.ms()
    esc = m.seg.apps[2].stack.esc
    before = esc.frames
    assert m.cycle() is None and esc.frames == before + 1     # processed, then lost
    m.ms(2)
    texts = [e.split(" ", 1)[1] for e in m.events]
    assert texts[0].startswith("wire fault 1 ethercat lost_frame: frame ")
    assert "on its way to bridge 2's port 0" in texts[0]
    assert "on its way back to the master" in texts[-1] and len(texts) == 3


def test_a_working_counter_off_by_one_on_the_process_data_only():
    m = Master()
    m.to_op()
    m.chains[0].inject_wire_fault("ethercat", "wkc", every=2, count=3)
    m.ms()
    assert m.one(E.BRD, 0, E.REG_TYPE, bytes(1))[1] == 3     # no LRW: not a message
    wkcs = [c[0] for c in m.run(8) if c is not None]
    assert wkcs == [9, 8, 9, 8, 9, 8, 9, 9]
    m.chains[0].inject_wire_fault("ethercat", "wkc", delta=1, datagram="any", count=1)
    m.ms()
    assert m.one(E.BRD, 0, E.REG_TYPE, bytes(1))[1] == 4
    m.ms()
    assert any("LRW working counter 9 -> 8" in e for e in m.events)
    assert any("BRD working counter 3 -> 4" in e for e in m.events)


def _sdo_upload(m: Master, station: int, index: int, counter: int) -> None:
    body = struct.pack("<HBHB", 0x2000, 0x40, index, 0) + bytes(4)
    mbx = (struct.pack("<HHBB", len(body), 0, 0, 0x03 | counter << 4) + body).ljust(128, b"\0")
    assert m.one(E.FPWR, station, ident.MBX_OUT_START, mbx)[1] == 1


def _sm1(m: Master, station: int) -> tuple[int, int, int]:
    """SM1's status, activate and PDI control bytes (0x080D-0x080F)."""
    data, _wkc = m.one(E.FPRD, station, E.REG_SM + 8 + 5, bytes(3))
    return data[0], data[1], data[2]


def test_a_lost_mailbox_answer_is_read_again_by_the_repeat_request():
    m = Master()
    m.to_op()
    station = 0x1002
    m.chains[0].inject_wire_fault("ethercat", "mailbox_lost", bridge=2, count=1)
    m.ms()
    _sdo_upload(m, station, 0x1000, 1)
    m.ms(2)
    status, activate, _pdi = _sm1(m, station)
    assert status & 0x08                                  # the answer waits in SM1
    # the frame that reads it is lost on its way back: the ESC has emptied SM1
    assert m.send((E.FPRD, station, ident.MBX_IN_START, bytes(128))) is None
    status, activate, pdi = _sm1(m, station)
    assert not status & 0x08
    # the master asks again (as SOEM does): toggle the repeat bit, wait for the ack
    assert m.one(E.FPWR, station, E.REG_SM + 8 + 6, bytes([activate ^ 0x02]))[1] == 1
    status, activate, pdi = _sm1(m, station)
    assert pdi & 0x02 == activate & 0x02 and status & 0x08
    answer, wkc = m.one(E.FPRD, station, ident.MBX_IN_START, bytes(128))
    assert wkc == 1
    length, _addr, _chan, kind = struct.unpack_from("<HHBB", answer)
    service, command, index, sub, value = struct.unpack_from("<HBHBI", answer, 6)
    assert (kind & 0x0F, service >> 12, command, index, sub) == (0x03, 3, 0x43, 0x1000, 0)
    assert value == m.seg.apps[1].dictionary.lookup(0x1000, 0)[1].dtype.decode(
        m.seg.apps[1].dictionary.read(0x1000, 0))
    m.ms()
    assert any("bridge 2's mailbox answer (SM1 emptied)" in e for e in m.events)
    # the other bridges' answers pass: only bridge 2's were chosen, and the count is spent
    _sdo_upload(m, 0x1001, 0x1000, 1)
    m.ms(2)
    assert m.send((E.FPRD, 0x1001, ident.MBX_IN_START, bytes(128))) is not None


def test_the_link_down_takes_the_bridges_behind_it_to_safeop_001b_and_back_to_op():
    m = Master()
    m.to_op()
    m.chains[0].inject_wire_fault("ethercat", "link_down", bridge=2, at=0.05, until=0.4)
    before = m.run(50)
    assert all(c is not None and c[0] == EXPECTED_WKC for c in before)
    during = m.run(340)
    assert all(c is not None and c[0] == 3 for c in during[5:])   # bridge 1 alone
    assert m.states() == [esm.OP] + [esm.SAFEOP | esm.ERROR_FLAG] * 2
    assert [app.stack.esc.al_code for app in m.seg.apps[1:]] == [esm.SM_WATCHDOG] * 2
    m.run(20)                                        # the cable is back: they answer
    assert m.line.plugged == (True, True, True)
    code, _wkc = m.one(E.FPRD, 0x1002, E.REG_AL_CODE, bytes(2))
    assert struct.unpack("<H", code)[0] == 0x001B
    for n in (1, 2):                                 # the master acknowledges, then OP
        m.one(E.FPWR, 0x1001 + n, E.REG_AL_CONTROL, struct.pack("<H", esm.SAFEOP | esm.ACK))
    m.cycle()
    for n in (1, 2):
        m.one(E.FPWR, 0x1001 + n, E.REG_AL_CONTROL, struct.pack("<H", esm.OP))
    after = m.run(10)
    assert m.states() == [esm.OP] * 3 and after[-1] is not None and after[-1][0] == 9
    texts = [e.split(" ", 1)[1] for e in m.events]
    assert texts == ["wire fault 1 ethercat link_down: begins",
                     "wire fault 1 ethercat link_down: the cable into bridge 2's port 0 "
                     "is pulled",
                     "wire fault 1 ethercat link_down: ends",
                     "wire fault 1 ethercat link_down: the cable into bridge 2's port 0 "
                     "is back"]


@pytest.mark.parametrize(("ms", "skipped"), [(2.5, 2), (3.0, 3)])
def test_a_late_cycle_skips_the_cycles_due_meanwhile(ms: float, skipped: int) -> None:
    """Late by 2.5 ms: the two cycles due meanwhile are skipped; by 3 ms, the one due at
    the instant the late one runs too (one cycle an instant)."""
    m = Master()
    m.to_op()
    drive = m.seg.apps[0].drive
    assert drive is not None
    start = drive.cycles
    m.chains[0].inject_wire_fault("ethercat", "late_cycle", ms=ms, every=10, count=2)
    m.ms(40)
    assert m.seg.faults is not None and m.seg.faults.skipped == 2 * skipped
    assert drive.cycles - start == 40 - 2 * skipped
    assert sum("ms late" in e for e in m.events) == 2


# -- determinism ------------------------------------------------------------------------------
STORM = """
[[wire.fault]]
door = "ethercat"
kind = "lost_frame"
probability = 0.05
seed = 7
at = 0.02
until = 0.3

[[wire.fault]]
door = "ethercat"
kind = "wkc"
probability = 0.1
seed = 11

[[wire.fault]]
door = "ethercat"
kind = "late_cycle"
every = 37
ms = 1.5

[[wire.fault]]
door = "ethercat"
kind = "link_down"
bridge = 3
at = 0.2
until = 0.35
"""


def test_a_scheduled_storm_gives_the_same_frames_and_records_on_two_runs():
    runs = []
    for _ in range(2):
        m = Master(STORM)
        m.to_op()
        got = m.run(400)
        positions = [c.snapshot(1).position for c in m.chains]
        runs.append((got, m.events, positions, m.states()))
    assert runs[0] == runs[1]
    got, events, _p, _s = runs[0]
    lost = sum(c is None for c in got)
    off = sum(c is not None and c[0] not in (9, 6, 3) for c in got)
    assert lost > 3 and off > 10 and any("ms late" in e for e in events)
    assert any(c is not None and c[0] == 6 for c in got)          # bridge 3 gone


# -- robustness ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def fuzzed() -> Master:
    """Three bridges in OP with every per-frame fault live, chosen by probability."""
    m = Master()
    m.to_op()
    for kind, params in (("lost_frame", {"way": "back"}), ("wkc", {"datagram": "any"}),
                         ("mailbox_lost", {}), ("lost_frame", {"bridge": 3})):
        m.chains[0].inject_wire_fault("ethercat", kind, probability=0.3, seed=5, **params)
    return m


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.binary(min_size=0, max_size=300), st.integers(0, 0x7FF))
def test_any_bytes_with_every_frame_fault_on_never_raise(fuzzed: Master, body: bytes,
                                                        length: int):
    """An EtherCAT header with any length and any datagrams behind it: the faults' tap
    parses what it finds and never raises (a frame comes back whole or is lost)."""
    m = fuzzed
    raw = b"\xff" * 6 + b"\x01" * 6 + b"\x88\xa4" + struct.pack("<H", 0x1000 | length) + body
    out = m.line.process(raw, m.kernel.now)
    assert out is None or len(out) == len(raw)
    m.ms()


def test_a_long_rain_of_faults_leaves_nothing_behind():
    """Faults of every kind installed and over, again and again, for 3 s of cycles: what
    is over is forgotten, nothing piles up between the threads, the tap goes away."""
    m = Master()
    m.to_op()
    device = m.chains[0]
    faults = m.seg.faults
    assert faults is not None
    sizes = []
    tracemalloc.start()
    try:
        for i in range(3000):
            if i % 50 == 0:
                m.events.clear()                      # (the test's own list)
                device.inject_wire_fault("ethercat", "lost_frame", probability=0.1, seed=i,
                                         until=0.03)
                device.inject_wire_fault("ethercat", "wkc", every=3, count=5)
                device.inject_wire_fault("ethercat", "late_cycle", ms=1.5, count=1)
                device.inject_wire_fault("ethercat", "link_down", bridge=3, at=0.01,
                                         until=0.02)
            m.cycle()
            if i % 1000 == 999:
                gc.collect()
                sizes.append(tracemalloc.get_traced_memory()[0])
    finally:
        tracemalloc.stop()
    m.ms(50)
    assert device.wire_faults.faults == [] and faults._done == [] and m.line.tap is None
    assert faults.lost > 50 and faults.changed == 5 * 60 and faults.skipped > 0
    assert m.line.plugged == (True, True, True)
    assert sizes[-1] - sizes[0] < 20_000, sizes           # bytes: flat after the first second

"""Wire faults in the model: the vocabulary, their schedule in virtual time, the host
line's faults where bytes leave the model, and the chain's (docs/wire-faults.md).

Exact bytes: the replies are 6.6's (``Px.1=0`` after power-up, ``P1.2=123``), the echo
ch. 3 K23 8's; the timing is the kernel's (integer ns).
"""

from __future__ import annotations

import pytest

from coolmuscle.chain.daisy import Chain
from coolmuscle.chain.machine import MachineFileError, parse_machine
from coolmuscle.device.uart import Frame, as_read_at
from coolmuscle.device.wire import Generator, describe, wire_fault
from coolmuscle.sim.kernel import ms, seconds
from fixtures import collect_events


class Wire:
    """A chain with everything the host line hands out, stamped with virtual time."""

    def __init__(self, chain: Chain) -> None:
        self.chain = chain
        self.got: list[tuple[int, bytes]] = []
        chain.host_line.add_listener(lambda data: self.got.append((chain.kernel.now, data)))

    def send(self, text: str) -> None:
        self.chain.host_line.feed(text.encode() + b"\r")

    def run(self, s: float) -> None:
        self.chain.kernel.run(until=self.chain.kernel.now + seconds(s))

    def take(self) -> list[bytes]:
        out = [data for _t, data in self.got]
        self.got.clear()
        return out


@pytest.fixture
def wire(make_chain) -> Wire:
    return Wire(make_chain(motors=3))


def test_fault_free_chain_has_no_wire_hook_on_its_host_line(chain):
    assert chain.host_line.wire is None
    chain.inject_wire_fault("modbus-tcp", "no_reply")
    assert chain.host_line.wire is None          # only host-line and chain faults need it


def test_drop_count_1_drops_the_reply_not_its_echo_and_the_next_query_works(wire):
    wire.chain.inject_wire_fault("host-line", "drop", count=1)
    wire.send("?96.1")
    wire.send("?96.1")
    assert wire.take() == [b"?96.1\r\n", b"?96.1\r\n", b"Px.1=0\r\n"]


def test_drop_with_echo_counts_the_echo_as_a_message(wire):
    wire.chain.inject_wire_fault("host-line", "drop", count=1, echo=True)
    wire.send("?96.1")
    assert wire.take() == [b"Px.1=0\r\n"]


def test_garble_flips_the_named_bits_of_the_named_byte(wire):
    wire.chain.inject_wire_fault("host-line", "garble", byte=-3, xor=0x40, count=1)
    events = collect_events(wire.chain, ["wire"])
    wire.send("?96.1")
    assert wire.take() == [b"?96.1\r\n", b"Px.1=p\r\n"]       # '0' 0x30 ^ 0x40 = 'p'
    assert events[0].text == 'wire fault 1 host-line garble: "Px.1=0\\r\\n" byte 5 ' \
                             '0x30 -> 0x70'


def test_garble_by_the_generator_never_touches_the_line_end(wire):
    wire.chain.inject_wire_fault("host-line", "garble", seed=7)
    for _ in range(50):
        wire.send("?96.1")
    replies = [d for d in wire.take() if not d.startswith(b"?96.1")]
    assert len(replies) == 50 and all(r.endswith(b"\r\n") for r in replies)
    assert all(sum(a != b for a, b in zip(r, b"Px.1=0\r\n")) == 1 for r in replies)


def test_delay_holds_what_follows_behind_it(wire):
    wire.chain.inject_wire_fault("host-line", "delay", ms=100, count=1)
    wire.send("?96.1")
    wire.send("?99.1")
    assert wire.take() == [b"?96.1\r\n"]                      # the echo is not delayed
    wire.run(0.2)
    assert wire.got == [(ms(100), b"Px.1=0\r\n"), (ms(100), b"?99.1\r\n"),
                        (ms(100), b"Ux.1=8\r\n")]


def test_split_delivers_the_pieces_with_their_gaps(wire):
    wire.chain.inject_wire_fault("host-line", "split", pieces=3, gap_ms=10, count=1)
    wire.send("?96.1")
    wire.run(0.1)
    assert wire.got[1:] == [(0, b"Px"), (ms(10), b".1="), (ms(20), b"0\r\n")]


def test_duplicate(wire):
    wire.chain.inject_wire_fault("host-line", "duplicate", copies=3, count=1)
    wire.send("?96.1")
    assert wire.take() == [b"?96.1\r\n"] + [b"Px.1=0\r\n"] * 3


def test_latency_delivers_in_timer_blocks_and_full_packets_at_once(wire):
    wire.chain.inject_wire_fault("host-line", "latency", ms=16, packet=62, until=1.0)
    wire.run(0.005)
    wire.send("?96.1")
    assert wire.got == []
    wire.run(0.02)
    assert wire.got == [(ms(16), b"?96.1\r\nPx.1=0\r\n")]
    wire.got.clear()
    wire.chain.kernel.run(until=ms(40))
    wire.send("?90.1")                                      # a long listing: 62-byte packets
    first = wire.take()
    assert [len(b) for b in first] == [62] * (len(first))
    wire.run(0.02)
    rest = wire.got
    assert rest and all(t == ms(48) for t, _ in rest) and len(rest[0][1]) < 62


def test_dead_line_loses_both_ways_then_comes_back(wire):
    wire.chain.inject_wire_fault("host-line", "dead", until=0.5)
    wire.send("P1.1=5")
    wire.send("?96.1")
    wire.run(0.6)
    assert wire.take() == []
    wire.send("P1.1")
    assert wire.take() == [b"P1.1\r\n", b"P1.1=0\r\n"]       # P1.1=5 never arrived


@pytest.mark.parametrize("kind, params", [("delay", {"ms": 5}), ("split", {}),
                                          ("latency", {"ms": 16})])
def test_a_host_set_to_another_frame_reads_garbage_through_the_faults_too(kind, params):
    """Paced, the motor frames its bytes with K82's parity (ch. 3 K82); a host whose port
    is 8N1 reads them as a UART would (.uart) whether a fault held them or not."""
    chain = Chain(pacing=True)
    chain.execute("K82.1=2")                                  # odd parity
    host = object()
    chain.host_line.set_host_baud(host, lambda: 38400)
    chain.host_line.set_host_frame(host, lambda: Frame())
    heard: list[bytes] = []
    plain: list[bytes] = []
    chain.host_line.add_listener(heard.append, host)
    chain.host_line.add_listener(plain.append)
    chain.inject_wire_fault("host-line", kind, **params)
    chain.host_line.write(b"Px.1=0\r\n")
    chain.kernel.run(until=chain.kernel.now + seconds(0.1))
    assert b"".join(plain) == b"Px.1=0\r\n" and len(plain) >= 1
    assert heard == [as_read_at(piece, 38400, 38400, Frame(parity="O"), Frame())
                     for piece in plain] != plain
    chain.close()


def test_every_hits_every_nth_reply(wire):
    wire.chain.inject_wire_fault("host-line", "drop", every=3)
    for _ in range(6):
        wire.send("?96.1")
    assert [d for d in wire.take() if d.startswith(b"Px")] == [b"Px.1=0\r\n"] * 4


def _drops(seed: int) -> list[int]:
    chain = Chain(motors=1)
    w = Wire(chain)
    chain.inject_wire_fault("host-line", "drop", probability=0.5, seed=seed)
    lost = []
    for i in range(64):
        w.send("?96.1")
        if b"Px.1=0\r\n" not in w.take():
            lost.append(i)
    chain.close()
    return lost


def test_probability_is_the_same_every_run_for_a_seed_and_differs_by_seed():
    first = _drops(11)
    assert first == _drops(11)
    assert first != _drops(12)
    assert 16 < len(first) < 48


def test_generator_is_splitmix64():
    # SplitMix64's first outputs for seed 0 (Vigna's reference implementation)
    g = Generator(0)
    assert [g.next64() for _ in range(3)] == [0xE220A8397B1DCDAF, 0x6E789E6AA1B965F4,
                                              0x06C45D188009454F]


def test_faults_begin_at_at_and_end_at_until(wire):
    wire.chain.inject_wire_fault("host-line", "drop", at=1.0, until=2.0)
    wire.send("?96.1")
    assert b"Px.1=0\r\n" in wire.take()
    wire.run(1.5)
    wire.send("?96.1")
    assert b"Px.1=0\r\n" not in wire.take()
    wire.run(1.0)
    wire.send("?96.1")
    assert b"Px.1=0\r\n" in wire.take()


def test_clear_ends_a_fault_at_once(wire):
    number = wire.chain.inject_wire_fault("host-line", "dead")
    assert wire.chain.clear_wire_faults(number) == 1
    wire.send("?96.1")
    assert wire.take() == [b"?96.1\r\n", b"Px.1=0\r\n"]


@pytest.mark.parametrize("table, message", [
    ('door = "host-line"\nkind = "lost"', "host-line has no fault kind 'lost'"),
    ('door = "usb"\nkind = "drop"', "unknown wire-fault door 'usb'"),
    ('door = "host-line"\nkind = "drop"\nms = 5', "takes no parameter 'ms'"),
    ('door = "host-line"\nkind = "delay"\nms = -1', "ms must be 0..60000"),
    ('door = "host-line"\nkind = "drop"\nevery = 2\nprobability = 0.5',
     "every or probability, not both"),
    ('door = "host-line"\nkind = "dead"\ncount = 1', "a lasting fault holds"),
    ('door = "chain"\nkind = "power_off"', "motor must be an integer 1..15"),
    ('door = "host-line"\nkind = "drop"\nat = 2\nuntil = 1', "until must be a number 2..1e+09"),
    (f'door = "host-line"\nkind = "drop"\nat = {10 ** 400}', "at must be a number 0..1e+09"),
    (f'door = "host-line"\nkind = "delay"\nms = {10 ** 400}', "ms must be 0..60000"),
])
def test_machine_file_refuses_bad_wire_faults_naming_the_key(table, message):
    with pytest.raises(MachineFileError, match="wire.fault\\[1\\]") as info:
        parse_machine(f"[[wire.fault]]\n{table}\n", "m.toml")
    assert message in str(info.value)


def test_machine_file_schedules_wire_faults(make_chain):
    machine = parse_machine('[[wire.fault]]\ndoor = "host-line"\nkind = "drop"\nat = 0.5\n'
                            'count = 1\n', "m.toml")
    assert machine.wire == [wire_fault("host-line", "drop", {"at": 0.5, "count": 1})]
    w = Wire(make_chain(machine=machine))
    w.run(1.0)
    w.send("?96.1")
    w.send("?96.1")
    assert w.take() == [b"?96.1\r\n", b"?96.1\r\n", b"Px.1=0\r\n"]


def test_machine_file_refuses_a_chain_fault_for_a_motor_not_there(make_chain):
    machine = parse_machine('[[wire.fault]]\ndoor = "chain"\nkind = "power_off"\n'
                            'motor = 4\n', "m.toml")
    with pytest.raises(MachineFileError, match="no motor ID4"):
        make_chain(motors=3, machine=machine)


def test_every_kind_is_described_for_the_web_page():
    doors = describe()
    assert list(doors) == ["host-line", "chain", "modbus-rtu", "modbus-tcp", "enip",
                           "ethercat"]
    kinds = {door: [k["kind"] for k in d["kinds"]] for door, d in doors.items()}
    assert kinds["host-line"] == ["drop", "garble", "delay", "split", "duplicate",
                                  "latency", "dead"]
    assert kinds["modbus-rtu"] == ["no_reply", "late", "exception", "bad_crc",
                                   "wrong_slave", "silence"]
    assert kinds["ethercat"] == ["lost_frame", "wkc", "mailbox_lost", "link_down",
                                 "late_cycle"]


# -- the chain ----------------------------------------------------------------------------
def test_power_off_cuts_that_motor_and_the_ones_beyond(wire):
    wire.chain.inject_wire_fault("chain", "power_off", motor=2, until=1.0)
    for line in ("?96.1", "?96.2", "?96.3"):
        wire.send(line)
    assert wire.take() == [b"?96.1\r\n", b"Px.1=0\r\n", b"?96.2\r\n", b"?96.3\r\n"]


def test_power_cycle_brings_back_saved_data_only(wire):
    chain = wire.chain
    chain.execute("P1.2=123")
    chain.execute("B1.2")
    chain.execute("P1.2")
    chain.execute("END")
    chain.execute("$.2")
    chain.execute("P2.2=7")                  # not saved
    chain.execute("K55.2=9")                 # K parameters persist by themselves (ch. 3)
    chain.inject_wire_fault("chain", "power_off", motor=2, until=0.5)
    wire.run(1.0)
    for line in ("P1.2", "P2.2", "K55.2", "?1.2"):
        wire.send(line)
    assert wire.take() == [b"P1.2\r\n", b"P1.2=123\r\n", b"P2.2\r\n", b"P2.2=0\r\n",
                           b"K55.2\r\n", b"K55.2=9\r\n", b"?1.2\r\n", b"P1.2\r\n"]


def test_power_cycle_with_a_store_loads_the_snapshot(make_chain, tmp_path):
    chain = make_chain(motors=2, state_dir=tmp_path)
    chain.execute("P1.2=55")
    chain.execute("$.2")
    chain.execute("P1.2=66")
    chain.inject_wire_fault("chain", "power_off", motor=2, until=0.1)
    chain.kernel.run(until=seconds(0.2))
    assert chain.get_register(2, "P", 1) == 55


def test_power_off_stops_the_motor_and_its_banks(wire):
    chain = wire.chain
    chain.execute("S.2=10, A.2=100, P.2=100000, ^.2")
    wire.run(0.5)
    chain.inject_wire_fault("chain", "power_off", motor=2)
    wire.run(5.0)
    snap = chain.snapshot(2)
    assert not snap.enabled and abs(snap.speed_pps) < 1e-6 and snap.position < 10000


def test_power_off_id1_kills_the_host_line(wire):
    wire.chain.inject_wire_fault("chain", "power_off", motor=1, until=1.0)
    wire.send("?96.1")
    assert wire.take() == []
    wire.run(1.5)
    wire.send("?96.1")
    assert wire.take() == [b"?96.1\r\n", b"Px.1=0\r\n"]


def test_a_motor_a_machine_file_keeps_off_at_power_up_powers_up_when_it_ends(make_chain):
    machine = parse_machine('[[wire.fault]]\ndoor = "chain"\nkind = "power_off"\n'
                            'motor = 2\nuntil = 0.5\n', "m.toml")
    chain = make_chain(motors=2, machine=machine)
    assert not chain.snapshot(2).enabled and chain.snapshot(1).enabled   # K68=1: servo on
    chain.kernel.run(until=seconds(1.0))
    assert chain.snapshot(2).enabled


def test_link_break_cuts_the_motors_beyond_which_keep_running(wire):
    chain = wire.chain
    chain.execute("S.3=100, A.3=100, P.3=20000, ^.3")
    chain.inject_wire_fault("chain", "link_break", motor=2, until=3.0)
    wire.send("]")
    wire.send("?96.2")
    wire.send("?96.3")
    assert wire.take() == [b"]\r\n", b"?96.2\r\n", b"Px.2=0\r\n", b"?96.3\r\n"]
    wire.run(3.5)
    assert chain.snapshot(3).position == 20000       # the pause never reached it
    wire.send("?96.3")
    assert wire.take() == [b"?96.3\r\n", b"Px.3=20000\r\n"]


def test_link_break_of_the_last_motor_is_refused(wire):
    with pytest.raises(ValueError, match="last on the chain"):
        wire.chain.inject_wire_fault("chain", "link_break", motor=3)


def test_each_fault_is_a_wire_event(wire):
    events = collect_events(wire.chain, ["wire"])
    wire.chain.inject_wire_fault("chain", "power_off", motor=3, until=0.25)
    wire.run(0.5)
    assert [(e.time, e.motor, e.text, e.origin) for e in events] == [
        (0, 3, "wire fault 1 chain power_off: begins", "api"),
        (ms(250), 3, "wire fault 1 chain power_off: ends", "api")]


# -- the trace --------------------------------------------------------------------------
def test_a_trace_counts_what_the_wire_faults_did_at_their_instants(make_chain, tmp_path):
    from coolmuscle.tools.trace.recorder import trace
    machine = parse_machine('[[wire.fault]]\ndoor = "host-line"\nkind = "drop"\nat = 0.25\n'
                            'count = 2\n', "m.toml")
    chain = make_chain(machine=machine)
    w = Wire(chain)
    stream = trace(chain, tmp_path / "t.csv", 0.5)
    for at in (0.1, 0.3, 0.6, 0.9):
        chain.kernel.run(until=seconds(at))
        w.send("?96.1")
    chain.kernel.run(until=seconds(1.0))
    stream.close()
    rows = (tmp_path / "t.csv").read_text().splitlines()
    assert rows[0].endswith(",m1.encoder,wire")
    counts = {row.split(",")[0]: row.split(",")[-1] for row in rows[1:]}
    assert counts["0.300000000"] == "1" and counts["0.600000000"] == "2"
    assert counts["1.000000000"] == "2"


def test_a_trace_without_wire_faults_keeps_its_columns(chain, tmp_path):
    from coolmuscle.tools.trace.recorder import trace
    stream = trace(chain, tmp_path / "t.csv", 0.5)
    chain.kernel.run(until=seconds(1.0))
    stream.close()
    assert (tmp_path / "t.csv").read_text().splitlines()[0].endswith(",m1.encoder")


# -- fuzz: any fault of the vocabulary, any bytes ------------------------------------------
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from coolmuscle.device.wire import kinds  # noqa: E402


def _param_value(param: dict) -> st.SearchStrategy:
    if param["type"] == "bool":
        return st.booleans()
    if "choices" in param:
        return st.sampled_from(param["choices"])
    lo, hi = param.get("min", -1e6), param.get("max", 1e6)
    if param["type"] == "int":
        return st.integers(int(lo), int(hi))
    return st.floats(lo, min(hi, 2000.0), allow_nan=False)


@st.composite
def any_fault(draw: st.DrawFn) -> tuple[str, str, dict]:
    door = draw(st.sampled_from(["host-line", "chain", "modbus-rtu", "modbus-tcp", "enip"]))
    kind = draw(st.sampled_from([k.describe() for k in kinds(door)]))
    params = {p["name"]: draw(_param_value(p)) for p in kind["params"]
              if draw(st.booleans())}
    schedule = {"at": draw(st.floats(0, 1)), "until": draw(st.floats(1, 3))}
    if kind["motor"] != "none":
        schedule["motor"] = draw(st.integers(1, 2))
    if not kind["lasting"]:
        choice = draw(st.sampled_from(["every", "probability", "count", None]))
        if choice == "every":
            schedule["every"] = draw(st.integers(1, 5))
        elif choice == "probability":
            schedule["probability"] = draw(st.floats(0, 1))
            schedule["seed"] = draw(st.integers(0, 2**64 - 1))
        elif choice == "count":
            schedule["count"] = draw(st.integers(1, 5))
    return door, kind["kind"], {**schedule, **params}


LINES = st.sampled_from([b"?96.1\r", b"?96.2\r", b"P1.2=5\r", b"$.2\r", b"S.2=50, P.2=800, ^.2\r",
                         b"K81.1=1\r", bytes.fromhex("01 03 00 C8 00 02 45 F5"),
                         b"FFFFFFFFF\r", b"K81.1=0\r", b"]\r", b"\x00\xff\r", b"?99.1\r"])


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(faults=st.lists(any_fault(), max_size=6), lines=st.lists(LINES, max_size=25))
def test_any_faults_and_any_bytes_never_raise_and_keep_saved_data(faults, lines):
    chain = Chain(motors=2)
    try:
        chain.execute("P7.2=321")
        chain.execute("$.2")
        for door, kind, params in faults:
            try:
                chain.inject_wire_fault(door, kind, **params)
            except ValueError:
                pass                           # refused (a link after the last motor)
        for i, line in enumerate(lines):
            chain.host_line.feed(line)
            chain.modbus_request(1, bytes.fromhex("03 00 C8 00 02"), tcp=True)
            chain.kernel.run(until=seconds(0.2 * (i + 1)))
        chain.kernel.run(until=seconds(10))
        assert chain.wire_faults.lasting("chain", "power_off") is None
        assert chain.get_register(2, "P", 7) == 321      # saved: back after any power cycle
    finally:
        chain.close()


def test_the_pages_panel_refuses_schedule_keys_and_names_as_parameters(chain):
    """The web page's panel passes ``params`` as keywords: a schedule key or ``door`` /
    ``kind`` among them is a bad request, not a TypeError (and not a schedule by the
    back door); a huge number is refused in the model's words."""
    from coolmuscle.tools.web.actions import RequestError
    from coolmuscle.tools.web.wirefaults import WirePanel
    panel = WirePanel(chain, lambda fn, *args: fn(*args))
    for params in ({"door": "x"}, {"kind": "drop"}, {"at": 1}, {"until": 2}):
        with pytest.raises(RequestError, match="is no parameter of a fault"):
            panel.inject({"door": "host-line", "kind": "delay", "params": params})
    with pytest.raises(ValueError, match="ms must be 0..60000"):
        panel.inject({"door": "host-line", "kind": "delay", "params": {"ms": 10 ** 400}})
    assert chain.wire_faults.faults == []


def test_an_ethercat_fault_reaches_every_bridge_a_segment_may_have():
    """The bridge parameter spans a segment's bridges (a machine file allows 64)."""
    from coolmuscle.device.wire.schedule import wire_fault
    from coolmuscle.device.wire.vocabulary import MAX_BRIDGES
    assert wire_fault("ethercat", "link_down", {"until": 1},
                      {"bridge": MAX_BRIDGES}).params["bridge"] == MAX_BRIDGES
    with pytest.raises(ValueError, match=f"bridge must be 1..{MAX_BRIDGES}"):
        wire_fault("ethercat", "link_down", {"until": 1}, {"bridge": MAX_BRIDGES + 1})

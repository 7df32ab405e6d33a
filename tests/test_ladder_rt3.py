"""The application examples of cm-banks-rt3.txt §7 with a load on the shaft.

The golden transcripts (tests/transcripts/rt3-7.*.cml) run the examples as printed on
an unloaded motor; here a load is put on the plant (a hand holding the shaft: Coulomb
friction) and the trace shows what the logic does with it.
"""

from __future__ import annotations

from bank_support import Rig, rig
from coolmuscle.sim.kernel import NS_PER_MS, seconds
from coolmuscle.tools.trace.recorder import record

MS = NS_PER_MS


def speeds(r: Rig, trace: object, start: float, end: float) -> list[float]:
    return [trace.sample(1, t).speed  # type: ignore[attr-defined]
            for t in range(seconds(start), seconds(end), 5 * MS)]


def test_rt3_7_3_2_bidirectional_torque_limit_reverses() -> None:
    r = rig("K87=1", 'v1="Ix", v2=30, v3=-30,s1=-20, s2=20, t1=250', "p=1000000000",
            "s=0", "a=100", "L1", "v1>v2,s0=s1:^:t1,CL2", "END", "L2",
            "v1<v3,s0=s2:^:t1,t0", "END", firmware="rt3")
    r.clear()
    trace = record(r.chain)
    r.type("[L1", "S.1=20", "^.1")
    r.until(1)
    assert r.texts() == [] and min(speeds(r, trace, 0.1, 1)) > 1999
    r.motor().plant.coulomb_friction = 0.15      # 47 % of rated torque while moving
    r.until(3)
    # L1 flips with 7 steps (1.75 ms) then the 250 ms timer; L2 (through CL2) with 11
    # steps (2.75 ms) then the timer: the direction flips every 251.75 / 252.75 ms
    flips = [seconds(1.002)]
    for n in range(7):
        flips.append(flips[-1] + (251_750_000 if n % 2 == 0 else 252_750_000))
    assert [t for t, _ in r.printed] == flips
    assert r.texts() == ["S0.1=-20", "S0.1=20"] * 4
    for t in flips[:-1]:
        assert trace.sample(1, t + 200 * MS).speed * (
            -1 if r.texts()[flips.index(t)] == "S0.1=-20" else 1) > 1999
    r.motor().plant.coulomb_friction = 0.004
    r.clear()
    r.until(4)
    assert r.texts() == []                       # no more reversals without the load


def _speed_control(*extra: str) -> Rig:
    return rig("S=20,A=50,P=100000", "S1.1=20", "S2=0", 'V1="IX", V2=20, V3=0,v4=0,v5=5',
               "B100", "L100", "L1", *extra, "V3=V4-V2;", "V1>V2,S0=S2,CL2;", "END", "L2",
               "V1>V4,S0=S1,T0;", "V1<V3,S0=S2,S0=S1;", "END", firmware="rt3")


def test_rt3_7_3_3_bidirectional_torque_speed_control_stops_under_load() -> None:
    r = _speed_control("M0=V2+V5;")
    r.clear()
    trace = record(r.chain)
    r.type("[L1", "^")
    r.until(1)
    assert r.chain.get_register(1, "M", 0) == 25
    assert min(speeds(r, trace, 0.1, 1)) > 1999
    r.motor().plant.coulomb_friction = 0.1       # 31 % > V2 = 20
    r.until(4)
    loaded = speeds(r, trace, 1.2, 4)
    assert min(loaded) < 1 and max(loaded) > 1999    # S0 goes S2 = 0, back to S1, ...
    moved = trace.sample(1, seconds(4)).position - trace.sample(1, seconds(1)).position
    assert 1000 < moved < 4500                       # unloaded it would be 6000
    r.motor().plant.coulomb_friction = 0.004
    r.until(5)
    assert min(speeds(r, trace, 4.5, 5)) > 1999


def test_rt3_7_3_4_unidirectional_torque_speed_control() -> None:
    r = _speed_control()
    r.clear()
    trace = record(r.chain)
    r.type("K87=1", "M0=100", "[L1", "^")
    r.until(1)
    r.motor().plant.coulomb_friction = 0.1
    r.until(2)
    loaded = speeds(r, trace, 1.1, 2)
    # 1 ms scans: stopped as soon as the torque shows, restarted once it is gone: a creep
    assert min(loaded) < 1 and 10 < max(loaded) < 1000
    moved = trace.sample(1, seconds(2)).position - trace.sample(1, seconds(1.1)).position
    assert 1 < moved < 200
    assert r.chain.get_register(1, "M", 0) == 100    # 7.3.4 leaves M0 alone


def test_rt3_7_1_described_edges_and_levels() -> None:
    """Rising edge: start; high: one more speed count a scan; falling edge: stop."""
    r = rig("P.1=1000000000", "A.1=100", 'v1=1,v2=2,v3=0,v4="Sx",v5=1', "L1.1", "V3=I3;",
            "V3==v13,CL3,CL2", "v13=v3;", "end.1", "L2.1", "V3==v1,S0=v4:^.1,].1", "End.1",
            "L3.1", "V3==v1,S0=S0+v5,T0", "End.1", firmware="rt3")
    r.clear()
    trace = record(r.chain)
    r.type("[L1.1")
    r.until(0.25)
    r.chain.set_input(1, 3, True)
    r.until(1.25)
    assert r.texts() == ["S0.1=0"] + [f"S0.1={n}" for n in range(1, 10)]
    assert trace.sample(1, seconds(1.25)).speed > 800      # S0 = 9 at 1.2 s: 900 pps
    r.chain.set_input(1, 3, False)
    r.until(2)
    assert abs(trace.sample(1, seconds(2)).speed) < 1
    assert r.texts()[-1] == "Ux.1=8"


def test_rt3_7_2_analog_input_controls_the_speed() -> None:
    r = rig("K37=3", "K87=1", 'V1="AIN4"', "V2=4", "S0.1=0", "A0.1=50", "P0.1=1000000000",
            "L1.1", "S0.1=V1.1/V2.1;", "^.1", "END.1", firmware="rt3")
    trace = record(r.chain)
    r.type("[L1.1")
    for counts, pps in ((512, 12800), (100, 2500), (1023, 25500)):
        r.chain.set_analog(1, counts)
        r.wait(1)
        assert trace.sample(1, r.kernel.now).speed == __import__("pytest").approx(pps, abs=1)


def test_rt3_1_1_c_in_a_logic_bank_calls_that_logic_bank() -> None:
    """RT3 1.1 "I": "Use in a bank: L1.1 I1.1, C2.1, C3.1 END.1 ... If I1=true than C2
    else C3" and "W0": "I1.1,W0,C2.1": RT3 loads C# in a logic bank and calls logic bank
    # there (as CL#); CM2 refuses it (6.5: C is P only)."""
    r = rig("v1=1, v2=2", "L1.1", "I1.1,C2.1,C3.1", "END.1",
            "L2.1", "V5=v1", "END.1", "L3.1", "V5=v2", "END.1", firmware="rt3")
    assert "error" not in " ".join(r.texts()), r.texts()
    assert r.chain.execute("?L1.1") == ["I1.1, C2.1, C3.1"]
    r.clear()
    r.type("[L1.1")
    r.until(0.01)
    assert r.texts()[-1] == "V5.1=2"             # I1 off: the else part, logic bank 3
    r.chain.set_input(1, 1, True)
    r.until(0.3)
    assert r.texts()[-1] == "V5.1=1"             # I1 on: logic bank 2
    cm2 = rig("L1.1", "I1.1,C2.1,C3.1", "END.1")
    assert "error03.1: C is not allowed in bank.1" in cm2.texts()


def test_rt3_1_1_j_in_a_logic_bank_jumps_to_that_logic_bank() -> None:
    """J# in an RT3 logic bank is JL#: the other bank is scanned from then on."""
    r = rig("v1=1", "L1.1", "J2.1", "END.1", "L2.1", "V6=v1", "END.1", firmware="rt3")
    assert "error" not in " ".join(r.texts()), r.texts()
    r.clear()
    r.type("[L1.1")
    r.until(0.2)
    assert r.texts() and set(r.texts()) == {"V6.1=1"}

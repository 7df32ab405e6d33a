"""External encoder (cml-users-guide.txt 5.4; ch. 3 K71, K72; 6.6 ?76; 2.2.1 "CT", 5.4.3 "Ecnt").

The encoder is geared to the actual shaft position (or runs on its own); counts are
read in closed form and the index stop is solved, so an index run costs two events.
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from coolmuscle.chain.daisy import Chain
from coolmuscle.motor.signals.encoder import Gearing, gearing_from_config
from coolmuscle.sim.kernel import seconds
from coolmuscle.tools.trace.recorder import record
from fixtures import ChainFactory, new_chain


def _run(chain: Chain, *lines: str, until: float = 20.0) -> None:
    for line in lines:
        chain.execute(line)
    chain.kernel.run(until=seconds(until))


def _index_stop(chain: Chain) -> int:
    """When the index stop began: the first instant of the stop trajectory."""
    history = chain.motors[1].axis.history or []
    return [t for t, profile, *_ in history if profile.end_ns is not None][-1]


def test_5_4_1_index_operation_runs_until_the_count_reaches_p_and_does_not_return(
        make_chain: ChainFactory) -> None:
    """5.4.1: K71=1, P=10000, S=10, A=100: the count overruns by the stopping distance
    (1000 pps at 100 kpps²: 5 pulses) plus the servo lag when the count was seen."""
    chain = make_chain(traced=True)
    chain.motors[1].encoder.set_gearing(Gearing(ppr=1000))  # one encoder pulse per motor pulse
    events: list[str] = []
    chain.subscribe(lambda e: events.append(e.text) if e.kind == "status" else None)
    motor = chain.motors[1]
    before = chain.kernel.events_run
    _run(chain, "K71.1=1", "P.1=10000", "S.1=10", "A.1=100", "^.1")
    stop = _index_stop(chain)
    assert motor.encoder.count(stop - 1) == 9999 and motor.encoder.count(stop) == 10000
    lag = record(chain).sample(1, stop)
    overrun = 5 + (lag.command - lag.position)
    assert chain.execute("?76.1") == [f"Ecnt.1={10000 + int(overrun)}"] == ["Ecnt.1=10008"]
    assert chain.execute("?96.1") == ["Px.1=10008"]
    assert events == ["Ux.1=8"]
    assert chain.kernel.events_run - before <= 3  # start, solved stop, in-position


def test_5_4_1_index_is_not_affected_by_k72_and_counts_down_too(make_chain: ChainFactory) -> None:
    finals = []
    for k72 in (400, 32767):
        chain = make_chain(traced=True)
        chain.motors[1].encoder.set_gearing(Gearing(ppr=500, ratio=2.0))  # 1 count per pulse again
        _run(chain, f"K72.1={k72}", "K71.1=1", "P.1=-3000", "S.1=20", "A.1=200", "^.1")
        finals.append((chain.execute("?76.1"), chain.execute("?96.1")))
    assert finals[0] == finals[1]
    count = int(finals[0][0][0].split("=")[1])
    assert -3000 - 20 < count < -3000           # overrun past P going down


def test_5_4_1_a_and_b_index_counts_a_quarter_of_the_sub_count(make_chain: ChainFactory) -> None:
    """K71=3: four edges per cycle; "count value will be 1/4 integral part of sub-count"."""
    chain = make_chain(traced=True)
    chain.motors[1].encoder.set_gearing(Gearing(ppr=100))  # 0.1 encoder cycle per motor pulse
    motor = chain.motors[1]
    _run(chain, "K71.1=3", "P.1=50", "S.1=1", "A.1=10", "^.1")
    stop = _index_stop(chain)
    assert motor.encoder.count(stop - 1) == 49 and motor.encoder.count(stop) == 50
    # 100 pps: 0.5 pulse to stop at 10 kpps², 0.33 pulse of servo lag
    assert motor.axis.position() == pytest.approx(500 + 0.5 + 1 / 3, abs=0.01)


def test_5_4_1_index_on_an_encoder_that_moves_by_itself(make_chain: ChainFactory) -> None:
    """A conveyor encoder at 2000 pulses/s: the stop comes at the solved instant."""
    chain = make_chain(traced=True)
    chain.motors[1].encoder.set_gearing(Gearing(kind="independent", rate=2000.0))
    _run(chain, "K71.1=1", "P.1=5000", "S.1=10", "A.1=100", "^.1", until=10)
    assert _index_stop(chain) == seconds(2.5)
    assert chain.execute("?76.1") == ["Ecnt.1=20000"]   # it kept running after the stop


def test_5_4_1_a_stop_command_cancels_the_index_operation(make_chain: ChainFactory) -> None:
    chain = make_chain(traced=True)
    chain.motors[1].encoder.set_gearing(Gearing(ppr=1000))
    _run(chain, "K71.1=1", "P.1=10000", "S.1=10", "A.1=100", "^.1", until=2)
    _run(chain, "].1", until=3)
    position = chain.execute("?96.1")
    _run(chain, until=20)
    assert chain.execute("?96.1") == position == ["Px.1=2000"]


def test_5_4_1_a_new_speed_during_index_is_solved_again(make_chain: ChainFactory) -> None:
    chain = make_chain(traced=True)
    chain.motors[1].encoder.set_gearing(Gearing(ppr=1000))
    motor = chain.motors[1]
    _run(chain, "K71.1=1", "P.1=10000", "S.1=10", "A.1=100", "^.1", until=2)
    motor.write_state("ST", 40)                # St: the running rotation speeds up
    _run(chain, until=10)
    stop = _index_stop(chain)
    assert motor.encoder.count(stop - 1) == 9999 and motor.encoder.count(stop) == 10000


def test_5_4_2_feedback_operation_puts_the_load_on_the_count(make_chain: ChainFactory) -> None:
    """5.4.2: K71=4, K72=1000; with belt slip and backlash the motor goes further so
    that the load encoder reads exactly P."""
    chain = make_chain(traced=True)
    chain.motors[1].encoder.set_gearing(Gearing(slip=0.1, backlash=20.0))
    _run(chain, "K71.1=4", "K72.1=1000", "P.1=10000", "S.1=10", "A.1=100", "^.1", until=15)
    assert chain.execute("?76.1") == ["Ecnt.1=10000"]
    position = chain.motors[1].axis.position()
    assert position == pytest.approx(10000 / 0.9 + 10 + 0.125 / 0.9, abs=0.01)
    _run(chain, "P.1=2000", "^.1", until=30)    # back: the play is taken up the other way
    assert chain.execute("?76.1") == ["Ecnt.1=2000"]
    assert chain.motors[1].axis.position() == pytest.approx(2000 / 0.9 - 10 + 0.125 / 0.9,
                                                             abs=0.01)


def test_5_4_3_pulse_counting_with_v_ecnt(make_chain: ChainFactory) -> None:
    """5.4.3: K71=5 counts only; V1="Ecnt" reads the count (here a direct-mode branch
    stands in for the ladder bank of 2.2.3)."""
    chain = make_chain(traced=True)
    chain.motors[1].encoder.set_gearing(Gearing(ppr=1000))
    _run(chain, "K71.1=5", 'V1.1="Ecnt"', "S.1=10", "A.1=100", "P.1=3000", "^.1", until=5)
    _run(chain, "V1.1>5000, V3.1=50, V3.1=10", until=5)
    assert chain.execute("V3.1") == ["V3.1=10"]
    _run(chain, "P.1=10000", "^.1", until=15)
    assert chain.execute("?96.1") == ["Px.1=10000"]     # normal positioning
    _run(chain, "V1.1>5000, V3.1=50, V3.1=10", "V2.1=V1.1", until=15)
    assert chain.execute("V3.1") == ["V3.1=50"]
    assert chain.execute("V2.1") == ["V2.1=10000"]


def test_ch3_k71_a_phase_counts_rising_edges_by_direction(make_chain: ChainFactory) -> None:
    """A-phase: a rising edge each whole cycle going forward, half a cycle later going
    back; A&B: the integral part of a quarter of the sub-count."""
    counts = {}
    for k71 in (5, 7):
        chain = make_chain(traced=True)
        chain.motors[1].encoder.set_gearing(Gearing(ppr=10))  # one cycle per 100 motor pulses
        seen = []
        for target in (1020, 960, 940, 1000, 1050, 0, -60):
            _run(chain, f"K71.1={k71}", f"P.1={target}", "S.1=10", "A.1=100", "^.1",
                 until=chain.kernel.now / 1e9 + 2)
            seen.append(chain.motors[1].encoder.count())
        counts[k71] = seen
    assert counts[5] == [10, 10, 9, 10, 10, 0, -1]
    assert counts[7] == [10, 9, 9, 10, 10, 0, 0]


def test_2_2_1_v_states_ct_and_ecnt_and_rt3_cx_fx(make_chain: ChainFactory) -> None:
    chain = make_chain(traced=True)
    chain.motors[1].encoder.set_gearing(Gearing(ppr=1000))
    _run(chain, "K71.1=5", 'V1.1="CT"', 'V2.1="Ecnt"', "S.1=10", "P.1=1234", "^.1", until=5)
    _run(chain, "V3.1=V1.1", "V4.1=V2.1")
    assert chain.execute("V3.1") + chain.execute("V4.1") == ["V3.1=1234", "V4.1=1234"]
    rt3 = make_chain(firmware="rt3", traced=True)
    rt3.motors[1].encoder.set_gearing(Gearing(ppr=1000))
    _run(rt3, "K71.1=5", 'V1.1="Cx"', 'V2.1="Fx"', "S.1=10", "P.1=5000", "^.1", until=2)
    _run(rt3, "V3.1=V1.1", "V4.1=V2.1", until=2)
    assert rt3.execute("V4.1") == ["V4.1=1000"]          # 1000 pulses/s while cruising
    assert 1900 < int(rt3.execute("V3.1")[0].split("=")[1]) < 2000


def test_the_trace_carries_the_encoder_count(make_chain: ChainFactory) -> None:
    chain = make_chain(traced=True)
    chain.motors[1].encoder.set_gearing(Gearing(ppr=1000))
    _run(chain, "K71.1=5", "S.1=10", "A.1=100", "P.1=2000", "^.1", until=3)
    rec = record(chain)
    assert rec.sample(1, seconds(1.0)).encoder == int(rec.sample(1, seconds(1.0)).position)
    assert rec.sample(1, seconds(3)).encoder == 2000
    assert "m1.encoder" in rec.header()


def test_ch3_k71_change_keeps_the_count_and_frees_inputs_1_and_2(make_chain: ChainFactory) -> None:
    chain = make_chain(traced=True)
    chain.motors[1].encoder.set_gearing(Gearing(ppr=1000))
    encoder = chain.motors[1].encoder
    _run(chain, "K71.1=5", "S.1=10", "P.1=700", "^.1", until=2)
    assert not encoder.uses_input(2) and encoder.uses_input(1)
    _run(chain, "K71.1=7", until=2)
    assert encoder.uses_input(2) and chain.execute("?76.1") == ["Ecnt.1=700"]
    _run(chain, "P.1=900", "^.1", until=4)
    assert chain.execute("?76.1") == ["Ecnt.1=900"]
    _run(chain, "K71.1=0", "P.1=0", "^.1", until=6)
    assert chain.execute("?76.1") == ["Ecnt.1=900"] and not encoder.uses_input(1)


def test_cm1_k63_counts_with_k88_resolution(make_chain: ChainFactory) -> None:
    chain = make_chain(firmware="cm1", traced=True)
    chain.motors[1].encoder.set_gearing(Gearing())
    chain.execute("(.1")
    _run(chain, "K88.1=1500", "K63.1=2", "S.1=10", "P.1=501", "^.1", until=3)
    assert chain.execute("?76.1") == ["Ecnt.1=751"]    # 1500 ppr encoder, 1000 ppr motor


def test_machine_file_encoder_tables() -> None:
    assert gearing_from_config({}) == Gearing()
    g = gearing_from_config({"kind": "load", "ratio": 0.5, "ppr": 2048, "slip": 0.02,
                             "backlash": 3})
    assert (g.ratio, g.ppr, g.slip, g.backlash) == (0.5, 2048, 0.02, 3.0)
    assert gearing_from_config({"kind": "independent", "rate": 150, "start": 1,
                                "stop": 4}).stop == 4.0
    for bad, message in (({"kind": "magnetic"}, "kind must be"), ({"ppr": 0}, "ppr"),
                         ({"slip": 1}, "slip"), ({"backlash": -1}, "backlash"),
                         ({"ratio": "two"}, "ratio")):
        with pytest.raises(ValueError, match=message):
            gearing_from_config(bad)


@settings(max_examples=15, deadline=None)
@given(target=st.integers(-20000, 20000), speed=st.integers(1, 60),
       accel=st.integers(20, 500), ppr=st.sampled_from([200, 1000, 1024, 3000]),
       k71=st.sampled_from([1, 2, 3]))
def test_5_4_1_index_stop_is_solved_at_the_count_edge(target: int, speed: int, accel: int,
                                                       ppr: int, k71: int) -> None:
    """Property: the stop starts at the very nanosecond the count becomes P, and the
    count never comes back (no overrun correction)."""
    chain = new_chain(traced=True)
    chain.motors[1].encoder.set_gearing(Gearing(ppr=ppr))
    motor = chain.motors[1]
    _run(chain, f"K71.1={k71}", f"P.1={target}", f"S.1={speed}", f"A.1={accel}", "^.1",
         until=0)
    chain.kernel.run_until(lambda: not motor.axis.moving, seconds(100_000))
    if target == 0:
        assert motor.encoder.count() == 0
        return
    stop = _index_stop(chain)
    step = 1 if target > 0 else -1
    assert motor.encoder.count(stop) == target
    assert motor.encoder.count(stop - 1) == target - step
    final = motor.encoder.count()
    assert (final - target) * step >= 0


def test_signal_modules_import_no_clock_sockets_or_threads() -> None:
    """docs/architecture.md rule 1 for the signal models (pulses, analog, encoder, jog)."""
    import ast
    from pathlib import Path

    import coolmuscle.motor
    package = Path(coolmuscle.motor.__file__).parent
    for name in ("motion/trajectory", "signals/pulses", "signals/manual", "signals/analog",
                 "signals/analog_control", "signals/analog_output", "signals/encoder"):
        tree = ast.parse((package / f"{name}.py").read_text())
        for node in ast.walk(tree):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            for imported in names:
                assert imported.split(".")[0] not in {"time", "asyncio", "socket",
                                                      "threading"}, (name, imported)

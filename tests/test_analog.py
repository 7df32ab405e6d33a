"""Analog input, control and output (cml-users-guide.txt ch. 3 K35, K38-K41; 5.5, K74-K77).

Golden transcripts: tests/transcripts/ch3-k38-*.cml and ch3-k40-*.cml.  These tests
cover the sources, the K39 filter, when the loop runs, torque control and torque
feedback, the analog output and the CM1 mapping.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from coolmuscle.chain.daisy import Chain
from coolmuscle.motor.signals.analog import (
    Constant,
    Ramp,
    Sine,
    Table,
    TorqueSensor,
    adc,
    source_from_config,
)
from coolmuscle.motor.signals.analog_control import SAMPLE_NS, TICK_NS, friction_nm
from coolmuscle.motor.signals.analog_output import output_volts, volts_to_register
from coolmuscle.sim.kernel import seconds
from coolmuscle.tools.trace.recorder import record
from fixtures import ChainFactory, new_chain


# -- the converter and the sources ------------------------------------------------------
def test_ch3_k38_converter_divides_5_volts_into_1024() -> None:
    assert [adc(v) for v in (0.0, 0.2, 2.5, 4.8, 5.0, 7.0, -1.0)] == \
        [0, 40, 512, 983, 1023, 1023, 0]
    assert adc(math.nan) == 0 and adc(math.inf) == 1023


def test_source_kinds_are_closed_form_functions_of_time() -> None:
    ramp = Ramp(1.0, 3.0, seconds(1), seconds(2))
    assert [ramp.volts(seconds(t)) for t in (0, 1, 2, 3, 9)] == [1.0, 1.0, 2.0, 3.0, 3.0]
    assert not ramp.changing(seconds(0.5)) and ramp.next_change(seconds(0.5)) == seconds(1)
    assert ramp.changing(seconds(1.5)) and ramp.next_change(seconds(3)) is None
    sine = Sine(2.5, 1.0, 2.0)
    assert sine.volts(seconds(0.125)) == pytest.approx(3.5)
    table = Table([(0, 1.0), (1, 3.0), (2, 3.0), (3, 0.0)])
    assert table.volts(seconds(0.5)) == 2.0 and table.next_change(seconds(1.5)) == seconds(2)
    steps = Table([(0, 1.0), (1, 3.0)], interpolate="step")
    assert steps.volts(seconds(0.999)) == 1.0 and steps.volts(seconds(1)) == 3.0
    assert steps.next_change(0) == seconds(1) and steps.next_change(seconds(1)) is None
    looped = Table([(0, 0.0), (1, 2.0)], repeat=True)
    assert looped.volts(seconds(2.5)) == pytest.approx(1.0)


def test_machine_file_analog_tables(tmp_path: Path) -> None:
    (tmp_path / "knob.csv").write_text("time_s,volts\n0,0.5\n# a comment\n2,4.5\n")
    assert source_from_config({"kind": "constant", "value": 2.5}).volts(0) == 2.5
    assert source_from_config({"value": 512, "unit": "counts"}).volts(0) == 2.5
    ramp = source_from_config({"kind": "ramp", "from": 0.2, "to": 4.8, "start": 1,
                               "duration": 2})
    assert ramp.volts(seconds(2)) == pytest.approx(2.5)
    sine = source_from_config({"kind": "sine", "offset": 2.5, "amplitude": 2,
                               "frequency": 0.5, "phase": 90})
    assert sine.volts(0) == pytest.approx(4.5)
    csv_source = source_from_config({"kind": "csv", "file": "knob.csv"}, base_dir=tmp_path)
    assert csv_source.volts(seconds(1)) == pytest.approx(2.5)
    sensor = source_from_config({"kind": "torque-sensor", "stiffness": 2e-4, "contact": 100})
    assert isinstance(sensor, TorqueSensor) and sensor.volts(0) == 2.5


@pytest.mark.parametrize("table, message", [
    ({"kind": "square"}, "kind must be"),
    ({"kind": "ramp", "from": 1}, "needs 'to'"),
    ({"kind": "ramp", "from": 1, "to": 2, "duration": 0}, "duration must be > 0"),
    ({"kind": "constant", "value": "high"}, "must be a number"),
    ({"kind": "constant", "value": 1, "unit": "mV"}, "unit must be"),
    ({"kind": "sine", "frequency": math.inf}, "finite"),
    ({"kind": "csv"}, "needs 'file'"),
    ({"kind": "csv", "file": "/nonexistent/knob.csv"}, "cannot read"),
])
def test_machine_file_analog_table_errors(table: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        source_from_config(table)


def test_machine_file_csv_rows_must_be_numbers(tmp_path: Path) -> None:
    (tmp_path / "bad.csv").write_text("0,1\n1,x\n")
    with pytest.raises(ValueError, match="bad.csv:2"):
        source_from_config({"kind": "csv", "file": str(tmp_path / "bad.csv")})


# -- K39 filter and when the loop runs --------------------------------------------------------
def test_ch3_k39_first_order_filter_at_5000_samples_per_second(make_chain: ChainFactory) -> None:
    """K39 unit "5[rad/sec] = 5000[times/sec]/1024": y += K39/1024 (x - y) per sample."""
    chain = make_chain(traced=True)
    motor = chain.motors[1]
    chain.set_param(1, 38, 5)                      # P data: the loop runs, nothing moves
    chain.set_param(1, 39, 64)
    chain.kernel.run(until=seconds(0.01))
    chain.set_analog(1, 800)
    start = chain.kernel.now
    alpha = 64 / 1024
    for n in range(1, 30):
        chain.kernel.run(until=start + n * TICK_NS)
        expected = 800 * (1 - (1 - alpha) ** (n * TICK_NS // SAMPLE_NS))
        assert motor.analog_control.filtered == pytest.approx(expected, rel=1e-9)


def test_ch3_k39_1024_is_no_filter_and_0_passes_nothing(make_chain: ChainFactory) -> None:
    chain = make_chain(traced=True)
    motor = chain.motors[1]
    chain.set_param(1, 38, 5)
    chain.set_param(1, 41, 1000)
    chain.set_param(1, 39, 1024)
    chain.set_analog(1, 983)
    chain.kernel.run(until=chain.kernel.now + TICK_NS)
    assert chain.execute("P.1") == ["P.1=1000"]
    chain.set_param(1, 39, 0)
    chain.set_analog(1, 512)
    chain.kernel.run(until=seconds(1))
    assert chain.execute("P.1") == ["P.1=1000"] and motor.analog_control.filtered == 983


def test_the_loop_sleeps_on_a_steady_input_and_costs_nothing(make_chain: ChainFactory) -> None:
    chain = make_chain(traced=True)
    chain.set_param(1, 41, 10000)
    chain.set_analog(1, 600)
    chain.kernel.run(until=seconds(2))
    assert chain.kernel.peek() is None             # settled: no periodic event left
    before = chain.kernel.events_run
    chain.kernel.run(until=seconds(100))
    assert chain.kernel.events_run == before


def test_the_loop_wakes_for_a_ramp_and_ticks_only_while_it_changes(
        make_chain: ChainFactory) -> None:
    chain = make_chain(traced=True)
    motor = chain.motors[1]
    chain.set_param(1, 41, 1000)
    chain.set_param(1, 39, 1024)
    motor.set_analog_source(Ramp(0.2, 4.8, seconds(5), seconds(1)))
    chain.kernel.run(until=seconds(4.9))
    assert motor.analog_control.ticks == 1         # 0 V -> 0.2 V at once, then asleep
    chain.kernel.run(until=seconds(5.5))
    assert motor.analog_control.ticks == 1 + 500   # one a millisecond from 5.001 s
    chain.kernel.run(until=seconds(10))
    assert motor.analog_control.ticks == 1 + 1000  # 5.001 .. 6.000 s, then asleep
    assert chain.kernel.peek() is None
    assert chain.execute("?96.1") == ["Px.1=1000"]


def test_ch3_k38_0_ignores_even_a_changing_input(make_chain: ChainFactory) -> None:
    chain = make_chain(traced=True)
    chain.set_param(1, 38, 0)
    chain.motors[1].set_analog_source(Sine(2.5, 2.0, 3.0))
    chain.kernel.run(until=seconds(2))
    assert chain.kernel.events_run == 0
    assert chain.execute("?96.1") == ["Px.1=0"]


def test_6_6_q74_reads_the_source_at_the_instant_asked(make_chain: ChainFactory) -> None:
    chain = make_chain(traced=True)
    chain.set_param(1, 38, 0)
    chain.motors[1].set_analog_source(Sine(2.5, 2.0, 1.0))
    chain.kernel.run(until=seconds(0.25))
    assert chain.execute("?74.1") == [f"ADI0.1={adc(4.5)}"]
    chain.kernel.run(until=seconds(0.75))
    assert chain.execute("?74.1") == [f"ADI0.1={adc(0.5)}"]


# -- position and speed control ---------------------------------------------------------------
def test_ch3_k38_1_negative_k41_turns_the_other_way(make_chain: ChainFactory) -> None:
    chain = make_chain(traced=True)
    chain.set_param(1, 41, -10000)
    chain.set_analog(1, 512)
    chain.kernel.run(until=seconds(2))
    assert chain.execute("?96.1") == ["Px.1=-5000"]


def test_ch3_k38_1_follows_a_sine_within_the_in_position_window_silently(
        make_chain: ChainFactory) -> None:
    """A slowly moving input: the motor follows its filtered value; the status stays
    in-position (no Ux report flood) because each step is within K55."""
    chain = make_chain(traced=True)
    motor = chain.motors[1]
    events = []
    chain.subscribe(events.append)
    chain.set_param(1, 41, 200)
    chain.set_param(1, 38, 0)
    motor.set_analog_source(Sine(2.5, 2.0, 0.5))
    chain.set_param(1, 38, 1)                      # starts at 2.5 V, Px=0
    chain.kernel.run(until=seconds(4))
    fraction = (adc(2.5 + 2.0 * math.sin(2 * math.pi * 0.5 * 4)) - 40.96) / 942.08
    start_fraction = (adc(2.5) - 40.96) / 942.08
    assert motor.axis.target() == pytest.approx(200 * (fraction - start_fraction), abs=2)
    assert [e.text for e in events if e.kind == "status"] == []


def test_ch3_k38_2_and_3_turn_one_way_up_to_k40(make_chain: ChainFactory) -> None:
    for mode, sign in ((2, 1), (3, -1)):
        chain = make_chain(traced=True)
        chain.set_param(1, 40, 1200)               # 20000 pps at 1000 ppr
        chain.set_param(1, 38, mode)
        chain.set_analog(1, 512)
        chain.kernel.run(until=seconds(1))
        assert chain.execute("?97.1") == [f"Sx.1={sign * 100}"]
        chain.set_analog(1, 1000)
        chain.kernel.run(until=seconds(2))
        assert chain.execute("?97.1") == [f"Sx.1={sign * 200}"]


def test_ch3_k38_2_not_functional_until_below_0_2_volts_once(make_chain: ChainFactory) -> None:
    chain = make_chain(traced=True)
    chain.set_analog(1, 700)
    chain.set_param(1, 38, 2)
    chain.kernel.run(until=seconds(1))
    assert chain.execute("?97.1") == ["Sx.1=0"]
    chain.set_analog(1, 30)
    chain.kernel.run(until=seconds(1.2))
    chain.set_analog(1, 700)
    chain.kernel.run(until=seconds(2))
    assert chain.execute("?97.1") == ["Sx.1=350"]  # 0.70 of 3000 min⁻¹ at 1000 ppr


def test_ch3_k38_speed_control_yields_to_a_commanded_motion_and_resumes(
        make_chain: ChainFactory) -> None:
    chain = make_chain(traced=True)
    chain.set_param(1, 40, 600)
    chain.set_param(1, 38, 2)
    chain.set_analog(1, 512)
    chain.kernel.run(until=seconds(1))
    chain.execute("S.1=20, A.1=100, P.1=20000")     # the motor is near 5000 by now
    chain.execute("^.1")
    chain.kernel.run(until=seconds(1.5))
    assert chain.execute("?97.1") == ["Sx.1=20"]
    chain.kernel.run(until=seconds(9))
    assert chain.execute("?97.1") == ["Sx.1=50"]


def test_ch3_k38_6_s_data_changes_a_running_continuous_rotation(make_chain: ChainFactory) -> None:
    chain = make_chain(traced=True)
    chain.execute("S.1=10, A.1=100, P.1=1000000000")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(0.5))
    chain.set_param(1, 40, 1200)
    chain.set_param(1, 38, 6)
    chain.set_analog(1, 1000)                      # above 4.8 V: the full K40
    chain.kernel.run(until=seconds(1.5))
    assert chain.execute("S.1") == ["S.1=200"]
    assert chain.execute("?97.1") == ["Sx.1=200"]


# -- torque control and torque feedback -----------------------------------------------------------
def test_ch3_k38_9_torque_control_accelerates_the_load_up_to_k40(make_chain: ChainFactory) -> None:
    chain = make_chain(traced=True)
    motor = chain.motors[1]
    chain.set_analog(1, 512)
    chain.execute("M.1=50")
    chain.set_param(1, 40, 600)
    chain.set_param(1, 38, 9)
    chain.set_param(1, 39, 1024)                   # no filter: the step acts at once
    chain.kernel.run(until=seconds(0.5))
    assert chain.execute("?97.1") == ["Sx.1=0"]
    chain.set_analog(1, 1000)                      # +M0 = 50 % of rated torque
    chain.kernel.run(until=seconds(0.5) + TICK_NS)
    assert chain.execute("?98.1") == ["Ix.1=50"]
    chain.kernel.run(until=seconds(1))
    assert chain.execute("?97.1") == ["Sx.1=100"]  # capped at K40
    torque = int(chain.execute("?98.1")[0].split("=")[1])
    friction = 100 * friction_nm(motor.plant, 10000.0, 1000) / motor.plant.rated_torque
    assert torque == round(friction) < 50
    assert chain.kernel.peek() is None             # steady at K40: the loop sleeps


def _torque_feedback(contact: float) -> tuple[Chain, list[str]]:
    """5.5's example: sensor 1 V per 0.2 N·m at 2.5 V, K76=250, K77=200 (0.4 N·m = 100),
    V15=25 (0.1 N·m), S0=100, P0=10000; the load is a spring from ``contact`` on."""
    chain = new_chain(traced=True)
    events: list[str] = []
    chain.subscribe(lambda e: events.append(e.text) if e.kind == "status" else None)
    chain.motors[1].set_analog_source(TorqueSensor(offset=2.5, volts_per_nm=5.0,
                                                   stiffness=1e-4, contact=contact))
    for line in ("K38.1=10", "K76.1=250", "K77.1=200", "V15.1=25", "S.1=100", "A.1=100",
                 "P.1=10000", "^.1"):
        chain.execute(line)
    return chain, events


def test_5_5_torque_feedback_holds_the_commanded_torque_on_a_spring() -> None:
    chain, events = _torque_feedback(contact=5000)
    motor = chain.motors[1]
    chain.kernel.run(until=seconds(8))
    # 0.1 N·m on 1e-4 N·m/pulse: 1000 pulses past the contact; the sensor reads 3.0 V
    assert motor.position() == pytest.approx(6000, abs=15)
    assert motor.analog_control.sensor_value() == pytest.approx(25, abs=1.5)
    assert chain.execute("?74.1") in (["ADI0.1=614"], ["ADI0.1=615"])
    assert events == []                            # still pushing: not in position
    chain.execute("V15.1=50")
    chain.kernel.run(until=seconds(14))
    assert motor.position() == pytest.approx(7000, abs=15)


def test_5_5_torque_feedback_ends_at_p0_when_nothing_pushes_back() -> None:
    chain, events = _torque_feedback(contact=50000)
    chain.kernel.run(until=seconds(5))
    assert chain.execute("?96.1") == ["Px.1=10000"]
    assert events == ["Ux.1=8"]
    assert chain.kernel.peek() is None             # the loop sleeps again


def test_5_5_torque_feedback_that_holds_the_motor_still_reports_nothing_more(
        make_chain: ChainFactory) -> None:
    """K38=10 with in-range but extreme gains (K74=1000, K75=500, K76=0, K77=-1000):
    the feedback's command stands still, and stays one command: no report repeats
    (an attack found ``Ux.1=8`` a thousand times a second while the motor stood)."""
    chain = make_chain(traced=True)
    events: list[tuple[int, str]] = []
    chain.subscribe(lambda e: events.append((e.time, e.text)) if e.kind == "status" else None)
    for line in ("K38.1=10", "K74.1=1000", "K75.1=500", "K76.1=0", "K77.1=-1000",
                 "S.1=100", "A.1=100", "P.1=421815", "^.1"):
        chain.execute(line)
    chain.kernel.run(until=seconds(1))
    before = len(events)
    assert before <= 1
    chain.kernel.run(until=seconds(4))
    assert len(events) == before
    assert chain.execute("?96.1") == ["Px.1=0"] and chain.execute("?97.1") == ["Sx.1=0"]


def test_5_5_a_stop_command_ends_torque_feedback() -> None:
    chain, _ = _torque_feedback(contact=50000)
    chain.kernel.run(until=seconds(0.3))
    chain.execute("].1")
    chain.kernel.run(until=seconds(2))
    position = chain.execute("?96.1")
    chain.kernel.run(until=seconds(4))
    assert chain.execute("?96.1") == position
    assert chain.motors[1].analog_control.feedback is None


# -- analog output -------------------------------------------------------------------------------
@pytest.mark.parametrize("k35, values, volts", [
    (0, {"target": 512.0}, 3.335),
    (1, {"target": 64.0}, 3.335),
    (2, {"position": -512.0}, 1.665),
    (2, {"position": 1536.0}, 1.665),             # beyond the range it repeats
    (3, {"position": 128.0}, 0.83),
    (4, {"error": 1024.0}, 0.83),
    (6, {"speed_pps": 20000.0}, 3.335),           # 1200 min⁻¹ of ±2400 at 1000 ppr
    (7, {"speed_pps": -2500.0}, 1.665),           # -150 min⁻¹ of ±300
    (8, {"torque": 100.0}, 0.83),
    (9, {"torque": 6.25}, 3.335),
])
def test_ch3_k35_analog_output_scales(k35: int, values: dict[str, float], volts: float) -> None:
    args = {"target": 0.0, "position": 0.0, "error": 0.0, "speed_pps": 0.0, "torque": 0.0}
    args.update(values)
    assert output_volts(k35, pulses_per_rev=1000, **args) == pytest.approx(volts)


def test_ch3_k35_analog_output_of_a_motor_and_its_register_value(make_chain: ChainFactory) -> None:
    chain = make_chain(traced=True)
    motor = chain.motors[1]
    chain.set_param(1, 35, 2)
    assert motor.analog_output_volts() == 2.5 and motor.analog_output() == 512
    chain.execute("S.1=10, A.1=100, P.1=512")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(2))
    assert motor.analog_output_volts() == pytest.approx(3.335, abs=1e-3)
    assert motor.analog_output() == volts_to_register(3.335) == 683
    samples = record(chain).sample(1, seconds(2))
    assert samples.analog_out == pytest.approx(3.335, abs=1e-3)


# -- CM1 -------------------------------------------------------------------------------------------
def test_cm1_k64_9_selects_k38_speed_or_position_control(make_chain: ChainFactory) -> None:
    chain = make_chain(firmware="cm1", traced=True)
    motor = chain.motors[1]
    chain.execute("(.1")                           # CM1 K68 is not "servo on at power-up"
    assert motor.analog_control.mode == 0          # K64=0: no analog function
    chain.set_param(1, 64, 9)
    chain.set_param(1, 41, 1000)
    assert motor.analog_control.mode == 1          # K38=1 (CM1 default): position
    chain.set_analog(1, 983)
    chain.kernel.run(until=seconds(1))
    assert chain.execute("?96.1") == ["Px.1=1000"]
    chain.set_param(1, 38, 0)
    assert motor.analog_control.mode == 2          # speed control


def test_constant_source_and_set_analog_agree(make_chain: ChainFactory) -> None:
    chain = make_chain(traced=True)
    motor = chain.motors[1]
    motor.set_analog_source(Constant(2.5))
    assert chain.snapshot(1).analog == 512
    chain.set_analog(1, 1023)
    assert chain.snapshot(1).analog == 1023 and chain.execute("?74.1") == ["ADI0.1=1023"]


def test_machine_file_tables_drive_the_motor_through_the_config_attributes(
        make_chain: ChainFactory) -> None:
    """The machine file loader sets ``analog_config`` / ``encoder_config`` on the motor
    (docs/machine-file.md); that drives the input and connects the encoder at once."""
    from coolmuscle.motor.signals.encoder import gearing_from_config
    chain = make_chain(traced=True)
    motor = chain.motors[1]
    motor.analog_config = source_from_config({"kind": "constant", "value": 512,
                                              "unit": "counts"})
    motor.encoder_config = gearing_from_config({"ppr": 500})
    assert chain.execute("?74.1") == ["ADI0.1=512"]
    chain.set_param(1, 71, 5)
    chain.set_param(1, 38, 0)
    chain.execute("S.1=10, P.1=2000")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(3))
    assert chain.execute("?76.1") == ["Ecnt.1=1000"]
    assert motor.encoder_config.ppr == 500 and motor.analog_config.volts(0) == 2.5


def test_5_6_7_modbus_analog_output_register_reads_k35(make_chain: ChainFactory) -> None:
    """K78+54 "Analog Output" (5.6.7 FC03 table) reads the K35 output: 683 for the
    current position 512 (3.335 V), as the device snapshot publishes it."""
    from coolmuscle.chain.firmware_modbus.registers import MotorMap, long_of
    chain = make_chain(traced=True)
    chain.set_param(1, 35, 2)
    chain.execute("S.1=10, A.1=100, P.1=512")
    chain.execute("^.1")
    chain.kernel.run(until=seconds(2))
    assert chain.snapshot(1).extra["analog_output"] == 683
    words = MotorMap(chain, 1, chain.get_param(1, 78), little=False).read_holding(
        chain.get_param(1, 78) + 54, 2)
    assert long_of(words[0], words[1], False) == 683


def test_trace_analog_out_uses_the_k35_of_each_instant(chain: Chain) -> None:
    # ch. 3 K35 changed midway: the first part of the trace keeps its own K35
    trace = record(chain)
    chain.execute("K35.1=2, S.1=10, A.1=100, P.1=5000")   # position output
    chain.execute("^.1")
    chain.kernel.run(until=seconds(1))
    early = trace.sample(1, seconds(0.5)).analog_out
    chain.execute("K35.1=8")                               # torque output
    chain.kernel.run(until=seconds(7))
    assert trace.sample(1, seconds(0.5)).analog_out == early
    assert early != 2.5                                    # a position reads off centre
    assert trace.sample(1, seconds(6.5)).analog_out == 2.5  # torque 0 at rest: centre

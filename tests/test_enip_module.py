"""The CM1 EtherNet/IP module's behaviour (cm1-ethernetip-interface-manual.txt ch. 3), in
virtual time.

The module (:class:`Cm1Module`) drives a real virtual CM1 through the device API;
each test checks what the motor then does, read back through the device API.
"""

from __future__ import annotations

import struct

import pytest

from coolmuscle.chain import Chain
from coolmuscle.frontends.enip.cm1.adapter import Cm1Module
from coolmuscle.sim.kernel import Kernel, seconds


@pytest.fixture
def rig():
    kernel = Kernel()
    chain = Chain(kernel, motors=1, firmware="cm1", state_dir=None)
    yield kernel, chain, Cm1Module(chain)
    chain.close()


def out(flag=1, p0=0, s0=100, a0=100, control=0, k52=0) -> bytes:
    """An output image (3.2): flag, P0, S0, A0, control word, K52 byte, little endian."""
    return struct.pack("<HiihBB", flag, p0, s0, a0, control, k52)


def inputs(module: Cm1Module) -> tuple[int, int, int]:
    return struct.unpack("<HHi", module.input_image())


def run(kernel: Kernel, t: float) -> None:
    kernel.run(until=kernel.now + seconds(t))


def test_3_1_power_up_input_image_reads_in_position_at_zero(rig):
    _, _, module = rig
    assert module.input_image() == bytes.fromhex("0000 0800 00000000")
    assert module.output_image() == bytes(14)     # 3.2 "All data bytes are 0 on power up"


def test_3_2_manual_example_values_move_to_100000_then_status_8(rig):
    kernel, chain, module = rig
    module.write_output(out(1, 100000, 100, 10, 1))
    run(kernel, 0.5)
    assert inputs(module)[1] == 0                 # 3.1.2: 0 = motor running
    run(kernel, 15)
    assert inputs(module) == (0, 8, 100000)
    assert chain.snapshot(1).position == 100000


def test_3_2_example_bytes_are_little_endian_p0_is_1000000(rig):
    """The data line of 3.2 verbatim: 40 42 0F 00 is 1,000,000 little endian (docs/fidelity.md)."""
    kernel, chain, module = rig
    module.write_output(bytes.fromhex("01 00 40 42 0F 00 64 00 00 00 0A 00 01 00"))
    assert chain.register_value(1, "P", 0) == 1_000_000
    assert chain.register_value(1, "S", 0) == 100
    assert chain.register_value(1, "A", 0) == 10
    run(kernel, 2)
    assert inputs(module)[1] == 0 and 0 < inputs(module)[2] < 1_000_000


def test_3_2_1_idle_flag_gates_writes_until_run(rig):
    kernel, chain, module = rig
    module.write_output(out(0, 5000, control=1))
    run(kernel, 1)
    assert chain.snapshot(1).position == 0 and chain.register_value(1, "P", 0) == 0
    module.write_output(out(1, 5000, control=1))  # flag to run: the pending word acts
    run(kernel, 2)
    assert chain.snapshot(1).position == 5000


def test_3_2_1_class1_idle_header_also_gates(rig):
    kernel, chain, module = rig
    module.write_output(out(1, 5000, control=1), run=False)
    run(kernel, 1)
    assert chain.snapshot(1).position == 0


def test_3_2_3_control_word_acts_on_change_only(rig):
    kernel, chain, module = rig
    module.write_output(out(p0=3000, control=1))
    run(kernel, 2)
    assert chain.snapshot(1).position == 3000
    module.write_output(out(p0=6000, control=1))  # same word again: nothing happens
    run(kernel, 2)
    assert chain.snapshot(1).position == 3000
    module.write_output(out(p0=6000, control=0))  # the PLC toggles through 0
    module.write_output(out(p0=6000, control=1))
    run(kernel, 2)
    assert chain.snapshot(1).position == 6000


def test_3_2_3_stop_decelerates_with_a0(rig):
    kernel, chain, module = rig
    module.write_output(out(p0=100000, s0=100, a0=10, control=1))
    run(kernel, 1.5)                              # at speed 10000 pps
    module.write_output(out(p0=100000, s0=100, a0=10, control=2))
    run(kernel, 0.5)
    assert 0 < chain.snapshot(1).speed_pps < 10000   # still decelerating (A0 = 10 kpps²)
    run(kernel, 1)
    snap = chain.snapshot(1)
    assert snap.speed_pps == 0 and snap.position < 100000 and inputs(module)[1] == 8


def test_3_2_3_disable_enable_and_home(rig):
    kernel, chain, module = rig
    module.write_output(out(control=4))
    run(kernel, 0.1)
    assert inputs(module)[1] == 16                # 3.1.2: 16 motor windings disabled
    module.write_output(out(control=3))
    run(kernel, 0.1)
    assert inputs(module)[1] == 8
    module.write_output(out(control=5))           # origin search starts: the motor runs
    run(kernel, 0.5)
    assert inputs(module)[1] == 0 and chain.snapshot(1).speed_pps != 0


def test_3_1_2_alarm_code_and_enable_recovers(rig):
    kernel, chain, module = rig
    chain.inject_fault(1, "encoder")
    run(kernel, 0.1)
    assert inputs(module)[1] == 1                 # position error overflow
    module.write_output(out(control=3))           # "can be used to re-enable after a motor error"
    run(kernel, 0.1)
    assert inputs(module)[1] == 8


def _running(kernel, chain, module):
    module.write_output(out(p0=100000, control=1))
    run(kernel, 0.5)


def _in_position(kernel, chain, module):
    module.write_output(out(p0=2000, control=1))
    run(kernel, 3)


def _position_error_overflow(kernel, chain, module):
    # a stopper 500 pulses out: the stepper loses its steps there and the command runs
    # on until Pe passes K56 = 1 kpulse (CM1 Appendix A K56 "Kpulses")
    chain.motors[1].geometry.stopper_cw = 500.0
    chain.set_param(1, 56, 1)
    module.write_output(out(p0=100000, s0=50, control=1))
    run(kernel, 2)


def _over_speed(kernel, chain, module):
    chain.inject_fault(1, "regeneration")        # CM1 K72 regeneration voltage


def _over_current_by_overload(kernel, chain, module):
    # a jam of 150 % of rated held for more than K57 ms (CM1 Appendix A K57)
    chain.set_param(1, 57, 200)
    chain.inject_fault(1, "overload", torque=150)
    run(kernel, 0.5)


def _over_current(kernel, chain, module):
    chain.inject_fault(1, "over_current")


def _windings_disabled(kernel, chain, module):
    module.write_output(out(control=4))
    run(kernel, 0.1)


def _over_temperature(kernel, chain, module):
    chain.inject_fault(1, "over_temperature")    # beyond K71


def _emergency_stop(kernel, chain, module):
    _running(kernel, chain, module)
    chain.execute("*.1")
    run(kernel, 0.5)


@pytest.mark.parametrize("cause, code", [
    (_running, 0), (_position_error_overflow, 1), (_over_speed, 2),
    (_over_current_by_overload, 4), (_over_current, 4), (_in_position, 8),
    (_windings_disabled, 16), (_over_temperature, 128), (_emergency_stop, 512)])
def test_3_1_2_each_motor_status_code_of_the_table(rig, cause, code):
    """3.1.2 "Motor Status Code": 0 running, 1 position error overflow, 2 over speed,
    4 over current, 8 in position, 16 windings disabled, 128 over temperature, 512
    emergency stop: the code the module sends for each condition (bytes 2-3 of 0x65)
    is the table's; it has no 64 (CML 6.6's "power module over current")."""
    kernel, chain, module = rig
    cause(kernel, chain, module)
    assert inputs(module)[1] == code
    assert chain.execute("?99.1") == [f"Ux.1={code}"]   # what the module reads of the motor


def test_3_2_4_k52_byte_sets_communication_mode(rig):
    _, chain, module = rig
    module.write_output(out(k52=0))
    assert chain.get_param(1, 52) == 0
    module.write_output(out(k52=1))
    assert chain.get_param(1, 52) == 10
    chain.set_param(1, 52, 0)                     # changed back "through the serial port"
    module.write_output(out(k52=1))               # unchanged byte: the module leaves it
    assert chain.get_param(1, 52) == 0


def test_3_1_1_bit0_when_the_motor_refuses_a_value(rig):
    kernel, chain, module = rig
    module.write_output(out(a0=0, control=1))     # A0 = 0 is out of range on the motor
    assert inputs(module)[0] & 0x0001
    run(kernel, 1)
    assert chain.snapshot(1).position == 0
    module.write_output(out(p0=100, a0=100, control=0))
    module.write_output(out(p0=100, a0=100, control=1))
    assert inputs(module)[0] == 0


@pytest.mark.parametrize("state, bit", [("timeout", 0x0002), ("absent", 0x0004),
                                        ("errors", 0x0001)])
def test_3_1_1_serial_line_faults_set_their_bit_and_freeze_inputs(rig, state, bit):
    kernel, chain, module = rig
    module.write_output(out(p0=2000, control=1))
    run(kernel, 0.2)
    frozen = inputs(module)[2]
    module.serial_fault(state)
    run(kernel, 2)
    code, _status, position = inputs(module)
    assert code == bit and position == frozen and chain.snapshot(1).position == 2000
    module.write_output(out(p0=0, control=0))
    module.write_output(out(p0=0, control=1))     # not delivered while the line is down
    run(kernel, 2)
    assert chain.snapshot(1).position == 2000
    module.serial_fault("ok")
    assert inputs(module) == (0, 8, 2000)


def test_reset_outputs_is_the_power_up_image(rig):
    kernel, chain, module = rig
    module.write_output(out(p0=2000, control=1))
    module.reset_outputs()
    assert module.output_image() == bytes(14)
    run(kernel, 2)
    assert chain.snapshot(1).position == 2000     # the move already started goes on


def test_3_2_2_a0_is_a_signed_short_and_a_negative_one_counts_as_its_size(rig):
    """3.2.2 "10-11 Short Integer ... Acceleration (A0)" (signed, as bytes 2-5 "Long
    Integer" are); CML 6.2 "A": "The negative value is treated as absolute value"."""
    kernel, chain, module = rig
    module.write_output(bytes.fromhex("01 00 b8 0b 00 00 0a 00 00 00 f6 ff 01 00"))  # A0 = -10
    assert inputs(module)[0] == 0                 # no motor error (3.1.1 bit 0)
    run(kernel, 0.5)
    assert inputs(module)[1] == 0                 # moving toward P0 = 3000
    run(kernel, 30)
    assert inputs(module) == (0, 8, 3000)
    # control word 2 with a negative A0 stops the motion (3.2.3 "2: Stop with A0")
    module.write_output(out(1, 200000, 100, 10, 0))
    module.write_output(out(1, 200000, 100, 10, 1))
    run(kernel, 1)
    module.write_output(out(1, 200000, 100, -10, 2))
    assert inputs(module)[0] == 0
    run(kernel, 5)
    stopped = chain.snapshot(1).position
    run(kernel, 1)
    assert inputs(module) == (0, 8, stopped) and stopped < 200000

"""One suite of client operations on three targets, same results.

The targets (tests/client_targets.py): the simulator in-process (``coolmuscle://``,
virtual time), over TCP (``socket://``, real time), and over a socat pseudo-terminal
opened by pyserial as a real serial port.  Every test below runs on each of them and
asserts the same values; ``test_the_three_targets_give_identical_results`` also runs
one scenario on all three and compares the records.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from client_targets import TARGETS, Target, make_target, target_fixture
from coolmuscle.client import CoolMuscle, MotorEvent
from coolmuscle.errors import (
    AlarmError,
    CmlSyntaxError,
    CoolMuscleTimeout,
    MotionInterruptedError,
    OutOfRangeError,
)
from coolmuscle.motor.status import Ux


@pytest.fixture(params=TARGETS)
def target(request: Any, tmp_path: Path) -> Iterator[Target]:
    yield from target_fixture(request.param, tmp_path, motors=2)


@pytest.fixture
def m(target: Target) -> Iterator[CoolMuscle]:
    client = target.open()
    try:
        yield client
    finally:
        client.close()


def settle(m: CoolMuscle) -> None:
    """Let the servo settle after in-position (K55 window) before reading Px."""
    m.poll(0.3)


def count_sent(m: CoolMuscle, text: bytes) -> list[int]:
    """Count the lines ``text`` the client writes from now on (a spy on the driver)."""
    counter = [0]
    write = m._driver.write

    def spy(data: bytes) -> None:
        counter[0] += data.count(text)
        write(data)
    m._driver.write = spy  # type: ignore[method-assign]
    return counter


def test_typed_queries(m: CoolMuscle) -> None:
    assert m.position == 0 and m.speed == 0 and m.torque == 0 and m.position_error == 0
    status = m.status
    assert status == 8 and Ux.IN_POSITION in status and isinstance(status, Ux)
    assert (m.inputs, m.outputs, m.temperature, m.voltage, m.analog, m.encoder_count) == \
        (0, 0, 40, 24.0, 0, 0)
    version = m.version
    assert (version.series, version.firmware, version.serial) == ("CM2", "3.10", "0802A12345")
    assert m.get_direct_data() == {"P": 0, "S": 10, "A": 100, "M": 100}
    assert m.echo is True and m.delimiter == b"\r\n"


def test_parameters_are_validated_before_sending_and_read_back(m: CoolMuscle) -> None:
    params = m.read_params()
    assert sorted(params) == list(range(20, 90)) and params[22] == 200 and params[37] == 3
    m.write_param(44, 200)
    assert m.read_param(44) == 200
    sent = count_sent(m, b"K44")
    with pytest.raises(OutOfRangeError):
        m.write_param(44, 0)                 # table 6.1: 1..500
    with pytest.raises(OutOfRangeError):
        m.write_param(25, 33333)             # digit-wise: one digit per input (6 on CM2)
    with pytest.raises(OutOfRangeError):
        m.write_param(87, 5)                 # not defined on CM2
    with pytest.raises(ValueError):
        m.write_param(20, 1)                 # would change this line's baud rate
    assert sent[0] == 0 and m.read_param(44) == 200


def test_registers_write_read_and_refusals(m: CoolMuscle) -> None:
    m.write_register("P", 3, 4000)
    m.write_register("S", 2, -250)
    m.write_register("V", 2, "abcd")
    m.write_register("V", 3, "px")
    m.write_register("A", 1, -50)           # 6.2: A stores its absolute value
    assert (m.read_register("P", 3), m.read_register("S", 2), m.read_register("V", 2),
            m.read_register("V", 3), m.read_register("A", 1)) == (4000, -250, "abcd", "Px", 50)
    for kind, index, value in (("M", 1, 101), ("V", 1, "toolong"), ("S", 16, 1),
                               ("A", 1, 0)):
        with pytest.raises(OutOfRangeError):
            m.write_register(kind, index, value)
    m.write_param(23, 17)                   # messages on: the motor's own error00
    with pytest.raises(OutOfRangeError, match="error00.1"):
        m.write_register("P", 300, 1)       # in the client's 600 bound, not allocated
    with pytest.raises(ValueError):
        m.read_register("X", 1)


def test_move_to_move_by_and_wait_in_position(m: CoolMuscle) -> None:
    events: list[MotorEvent] = []
    m.subscribe(events.append, kinds=["status"])
    assert m.move_to(2000, speed=200, accel=1000) == 0      # running right after ^
    assert m.wait_in_position(timeout=5) == 8
    settle(m)
    assert m.position == 2000
    m.move_by(-500)
    m.wait_in_position(timeout=5)
    settle(m)
    assert m.position == 1500 and m.get_direct_data()["P"] == 1500  # 6.2: stored absolute
    assert [e.text for e in events] == ["Ux.1=8", "Ux.1=8"]


def test_wait_listens_to_reports_and_polls_without_them(m: CoolMuscle) -> None:
    polls = count_sent(m, b"?99.1")
    m.move_to(1000, speed=200, accel=1000)
    m.wait_in_position(timeout=5)
    assert polls[0] == 1                     # the status right after ^; then the report
    m.write_param(23, 0)                     # ch. 3 K23: no reports
    polls[0] = 0
    m.move_to(11000, speed=200, accel=1000)  # 0.5 s virtual; polls every 0.05 s
    assert m.wait_in_position(timeout=5) == 8
    assert polls[0] >= 3


def test_continuous_rotation_and_stop(m: CoolMuscle) -> None:
    assert m.run(100, accel=1000) == 0
    m.poll(0.3)
    assert m.speed == 100 and m.status == 0
    m.stop()
    assert m.wait_in_position(timeout=5) == 8
    settle(m)
    assert m.speed == 0
    with pytest.raises(OutOfRangeError):
        m.run(40000)


def test_emergency_stop_release_free_enable(m: CoolMuscle) -> None:
    m.move_to(100000, speed=50, accel=100)
    assert m.emergency_stop() == Ux.EMERGENCY_STOP
    with pytest.raises(MotionInterruptedError) as caught:
        m.wait_in_position(timeout=5)
    assert caught.value.status == 512
    assert m.release_emergency_stop() == 8
    assert m.free() == Ux.MOTOR_FREE
    m.move_to(10)
    with pytest.raises(MotionInterruptedError):
        m.wait_in_position(timeout=5)
    assert m.enable() == 8


def test_origin_commands(m: CoolMuscle) -> None:
    m.move_to(1000, speed=200, accel=1000)
    m.wait_in_position(5)
    settle(m)
    m.set_origin()
    assert m.position == 0
    m.move_to(-800, speed=200, accel=1000)
    m.wait_in_position(5)
    m.go_origin()
    m.wait_in_position(5)
    settle(m)
    assert m.position == 0


def test_outputs(m: CoolMuscle) -> None:
    m.write_param(34, 3333)                  # every output: general use (ch. 3 K34 "3")
    m.set_output(1)
    m.set_output(3)
    assert m.outputs == 0b101 and m.get_output(1) and not m.get_output(2)
    m.set_output(1, False)
    assert m.outputs == 0b100
    with pytest.raises(OutOfRangeError):
        m.set_output(5)


def test_motor_errors_raise_typed_exceptions(m: CoolMuscle) -> None:
    assert m.send("hello") == []             # K23 without 16: the motor says nothing
    m.write_param(23, 17)
    with pytest.raises(CmlSyntaxError) as caught:
        m.send("hello")
    assert caught.value.number == 1 and "error01.1" in str(caught.value)
    with pytest.raises(OutOfRangeError):
        m.send("K44.1=0")
    assert m.send("?99.1") == ["Ux.1=8"] and m.send("S.1=55") == []


def test_input_reports_reach_subscribers(target: Target, m: CoolMuscle) -> None:
    m.write_param(23, 3)                     # in-position/alarm and input reports
    events: list[MotorEvent] = []
    m.subscribe(events.append, kinds=["input"])
    target.inject(lambda chain: chain.set_input(1, 3, True), after=0.05)
    event = m.wait_event(kind="input", timeout=3)
    assert (event.motor, event.text, event.value) == (1, "IN.1=04", 4)
    assert events == [event] and m.inputs == 4


def test_output_reports_reach_subscribers(m: CoolMuscle) -> None:
    m.write_param(34, 3333)
    m.write_param(23, 5)                     # in-position/alarm and output reports
    events: list[MotorEvent] = []
    m.subscribe(events.append, kinds=["output"])
    m.set_output(2)
    m.set_output(2, False)
    m.poll(0.05)
    assert [(e.text, e.value) for e in events] == [("OUT.1=02", 2), ("OUT.1=00", 0)]


def test_cr_line_ends_and_no_echo_are_learned(m: CoolMuscle) -> None:
    """K70=0 (CR) and K23 with 8 (no echo): nothing to configure on the host (ch. 3)."""
    m.write_param(70, 0)
    assert m.position == 0 and m.delimiter == b"\r"
    m.write_param(23, 9)
    assert m.echo is False
    m.move_to(800, speed=200, accel=1000)
    assert m.wait_in_position(timeout=5) == 8
    settle(m)
    assert (m.position, m.read_register("P", 0), m.echo) == (800, 800, False)
    m.write_param(23, 1)
    m.write_param(70, 1)
    assert m.position == 800 and m.echo is True and m.delimiter == b"\r\n"


def test_each_motor_of_the_chain_has_its_handle(m: CoolMuscle) -> None:
    m2 = m.motor(2)
    assert m.motor(2) is m2 and m2.id == 2 and m.motor(1) is m
    m2.move_to(700, speed=200, accel=1000)
    m2.wait_in_position(5)
    settle(m)
    assert (m.position, m2.position) == (0, 700)
    assert m2.version.motor == 2


def test_an_alarm_during_a_move_raises_with_the_ux_value(target: Target,
                                                          m: CoolMuscle) -> None:
    m.move_to(100000, speed=20, accel=100)
    target.inject(lambda chain: chain.motors[1].raise_alarm(1), after=0.2)
    with pytest.raises(AlarmError) as caught:
        m.wait_in_position(timeout=5)
    assert caught.value.status == 1
    assert caught.value.flags == Ux.POSITION_ERROR_OVERFLOW
    assert m.status == 1
    assert m.enable() == 8                   # servo on again clears the alarm


def test_a_motor_that_is_not_there_times_out(target: Target, m: CoolMuscle) -> None:
    start = time.monotonic()
    with pytest.raises(CoolMuscleTimeout, match=r"Px\.3"):
        m.motor(3).get_position()
    assert time.monotonic() - start < 1.5
    assert m.position == 0                   # the connection goes on


def test_save(m: CoolMuscle) -> None:
    m.write_register("P", 1, 1234)
    m.save()
    assert m.read_register("P", 1) == 1234


def test_upload_of_direct_lines_is_read_back(m: CoolMuscle) -> None:
    result = m.upload("S1.1=150\nP2.1=-700\nK44.1=150\nV1.1=\"Ux\"\n")
    assert result.ok and result.sent == 4
    assert (m.read_register("S", 1), m.read_register("P", 2), m.read_param(44),
            m.read_register("V", 1)) == (150, -700, 150, "Ux")


def scenario(m: CoolMuscle) -> dict[str, Any]:
    """A short session whose every result is recorded."""
    record: dict[str, Any] = {"version": m.version.text, "status": int(m.status)}
    m.write_param(44, 150)
    record["k44"] = m.read_param(44)
    m.write_register("V", 4, "Sx")
    record["v4"] = m.read_register("V", 4)
    record["start"] = int(m.move_to(1234, speed=300, accel=1000))
    record["arrived"] = int(m.wait_in_position(5))
    settle(m)
    record["position"] = m.position
    try:
        m.write_param(44, 501)
    except OutOfRangeError as error:
        record["refused"] = type(error).__name__
    record["params"] = m.read_params()
    return record


def test_the_three_targets_give_identical_results(tmp_path: Path) -> None:
    records = {}
    for name in TARGETS:
        target = make_target(name, tmp_path)
        try:
            with target.open() as client:
                records[name] = scenario(client)
        finally:
            target.close()
    assert records["inproc"] == records["tcp"] == records["pty"]
    assert records["inproc"]["position"] == 1234 and records["inproc"]["refused"] == \
        "OutOfRangeError"

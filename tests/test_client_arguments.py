"""The host library refuses bad arguments before anything is sent (principle 4: a
typed exception, never a TypeError from inside, never a line the motor would take for
something else), and reads back banks that hold the ``?96`` fence's own text (6.6)."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from coolmuscle import connect_async
from coolmuscle.client import CoolMuscle, connect
from coolmuscle.errors import InvalidArgumentError, OutOfRangeError


@pytest.fixture
def m() -> Any:
    motor = connect("coolmuscle://?mode=fast")
    yield motor
    motor.close()


BAD: dict[str, Callable[[CoolMuscle], Any]] = {
    "motor('2')": lambda m: m.motor("2"),
    "motor(None)": lambda m: m.motor(None),
    "motor(1.5)": lambda m: m.motor(1.5),
    "motor(True)": lambda m: m.motor(True),
    "move_by('x')": lambda m: m.move_by("x"),
    "move_to(None)": lambda m: m.move_to(None),
    "move_to(1.5)": lambda m: m.move_to(1.5),
    "move_to(10, speed='fast')": lambda m: m.move_to(10, speed="fast"),
    "run(None)": lambda m: m.run(None),
    "read_register(1, 1)": lambda m: m.read_register(1, 1),
    "read_register('P', '1')": lambda m: m.read_register("P", "1"),
    "write_register('P', 0, None)": lambda m: m.write_register("P", 0, None),
    "set_output('x')": lambda m: m.set_output("x"),
    "set_output(1, 'yes')": lambda m: m.set_output(1, "yes"),
    "get_output('x')": lambda m: m.get_output("x"),
    "send(123)": lambda m: m.send(123),
    "send(b'?96.1')": lambda m: m.send(b"?96.1"),
    "send('\u20ac')": lambda m: m.send("\u20ac"),
    "send('a\\rb')": lambda m: m.send("a\rb"),
    "send('?' * 513)": lambda m: m.send("?" * 513),
    "upload(123)": lambda m: m.upload(123),
    "upload('program.cml')": lambda m: m.upload("program.cml"),
    "wait_in_position('x')": lambda m: m.wait_in_position(timeout="x"),
    "wait_in_position(-1)": lambda m: m.wait_in_position(timeout=-1),
    "poll('x')": lambda m: m.poll("x"),
    "wait_event(timeout=None)": lambda m: m.wait_event(timeout=None),
    "read_param('x')": lambda m: m.read_param("x"),
    "write_param('x', 1)": lambda m: m.write_param("x", 1),
    "start_bank('x')": lambda m: m.start_bank("x"),
    "save('x')": lambda m: m.save("x"),
}


@pytest.mark.parametrize("call", sorted(BAD))
def test_bad_arguments_raise_invalid_argument_and_send_nothing(m: CoolMuscle, call: str) -> None:
    sent: list[bytes] = []
    write = m.port.write
    m.port.write = lambda data: (sent.append(bytes(data)), write(data))[1]
    m.get_position()                          # learn the firmware and echo first
    assert sent                               # (the spy sees what goes out)
    sent.clear()
    with pytest.raises(InvalidArgumentError):
        BAD[call](m)
    assert sent == []


@pytest.mark.parametrize("call", ["read_param(10)", "read_param(999)", "read_bank(0)",
                                  "read_bank(31)", "read_bank(0, ladder=True)"])
def test_numbers_the_firmware_lacks_are_out_of_range_before_sending(m: CoolMuscle,
                                                                     call: str) -> None:
    with pytest.raises(OutOfRangeError):
        eval(f"m.{call}", {"m": m})


@pytest.mark.parametrize("kwargs", [{"timeout": "x"}, {"firmware": "zz"}, {"motor": "a"},
                                    {"motor": 16}, {"poll_interval": -1}])
def test_connect_refuses_bad_options_before_opening(kwargs: dict[str, Any]) -> None:
    with pytest.raises(InvalidArgumentError):
        connect("coolmuscle://?mode=fast", **kwargs)
    with pytest.raises(InvalidArgumentError):
        asyncio.run(connect_async("coolmuscle://?mode=fast", **kwargs))


def test_connect_refuses_what_is_neither_a_url_nor_a_port() -> None:
    with pytest.raises(InvalidArgumentError):
        connect(None)


def test_async_motor_handles_refuse_bad_ids_too() -> None:
    async def session() -> None:
        async with await connect_async("coolmuscle://?mode=fast") as a:
            with pytest.raises(InvalidArgumentError):
                a.motor("2")
            with pytest.raises(InvalidArgumentError):
                await a.move_to(None)
    asyncio.run(session())


@pytest.mark.parametrize("k23", [None, 9])     # echo on (default), echo off (K23 8)
def test_6_6_a_bank_holding_the_fence_text_reads_back_in_order(k23: int | None) -> None:
    m = connect("coolmuscle://?mode=fast")
    try:
        if k23 is not None:
            m.send(f"K23.1={k23}")
        result = m.upload("B9.1\n?96.1\nP1.1\n?96.1\nEND\n")
        assert result.ok
        assert m.read_bank(9) == ["?96.1", "P1.1", "?96.1"]
        assert m.read_all_banks() == {"B9.1": ["?96.1", "P1.1", "?96.1"]}
        assert m.get_position() == 0             # the line is in step afterwards
    finally:
        m.close()


def test_upload_of_a_file_that_is_not_utf8_is_a_typed_error(m: CoolMuscle,
                                                           tmp_path: Path) -> None:
    path = tmp_path / "bin.cml"
    path.write_bytes(b"B1.1\n\xff\xfeP1.1\nEND\n")
    with pytest.raises(InvalidArgumentError, match="not UTF-8"):
        m.upload(path)
    with pytest.raises(InvalidArgumentError, match="directory"):
        m.upload(tmp_path)


def test_2_2_2_typed_calls_wait_for_the_end_of_an_open_bank_definition(m: CoolMuscle) -> None:
    m.send("B7.1")
    with pytest.raises(InvalidArgumentError, match="bank definition is open"):
        m.get_position()
    with pytest.raises(InvalidArgumentError):
        m.read_param(55)
    m.send("P1.1")
    m.send("END")
    assert m.read_bank(7) == ["P1.1"]
    assert m.get_position() == 0


def test_an_emergency_stop_from_another_thread_does_not_wait_for_a_wait() -> None:
    """2.1.2 "*": sent while another thread waits for in-position, it goes out at once."""
    import threading
    import time

    from coolmuscle.errors import CoolMuscleError

    m = connect("coolmuscle://?scale=1")        # real time: a wait takes wall time
    try:
        m.move_to(100000, speed=10, accel=100)   # 1,000 pps: about 100 s
        outcome: list[object] = []

        def wait() -> None:
            try:
                outcome.append(m.wait_in_position(timeout=6))
            except CoolMuscleError as exc:
                outcome.append(exc)
        waiter = threading.Thread(target=wait)
        waiter.start()
        time.sleep(0.3)
        start = time.monotonic()
        m.emergency_stop()
        took = time.monotonic() - start
        waiter.join(8)
        assert took < 2.0, f"the emergency stop waited {took:.1f} s behind the wait"
        assert outcome and not waiter.is_alive()
    finally:
        m.close()


def test_2_2_2_another_threads_call_does_not_land_inside_an_uploaded_bank() -> None:
    """With echo off an upload paces its lines by time; a call from another thread
    waits for END instead of going out between the bank's lines."""
    import threading

    m = connect("coolmuscle://?mode=fast")
    try:
        m.write_param(23, 8)                     # no echo (ch. 3 K23 8)
        program = "B1\n" + "\n".join(f"P{i}=100{i}" for i in range(1, 9)) + "\nEND\n"
        stop = threading.Event()

        def poll() -> None:
            while not stop.is_set():
                m.get_position()
        poller = threading.Thread(target=poll)
        poller.start()
        try:
            assert m.upload(program).ok
        finally:
            stop.set()
            poller.join(10)
        assert m.read_bank(1) == [f"P{i}.1=100{i}" for i in range(1, 9)]
    finally:
        m.close()


def test_6_6_a_bank_holding_its_own_listing_query_reads_back_with_echo_off() -> None:
    m = connect("coolmuscle://?mode=fast")
    try:
        m.send("K23.1=9")
        assert m.upload("B1.1\n?1.1\nP1.1=5\nEND\n").ok
        assert m.read_bank(1) == ["?1.1", "P1.1=5"]
        assert m.get_position() == 0 and m.echo is False
    finally:
        m.close()


def test_numpy_numbers_and_an_endless_wait_are_accepted() -> None:
    np = pytest.importorskip("numpy")
    m = connect("coolmuscle://?mode=fast", timeout=np.int64(1))
    try:
        assert m.motor(np.int64(2)).id == 2
        assert m.read_bank(np.int64(1)) == []
        m.set_output(1, np.bool_(False))
        m.move_to(np.int64(100), speed=np.int32(100), accel=100)
        assert m.wait_in_position(timeout=np.float32(5)) & 8
        assert abs(m.get_position() - 100) <= 5          # in position: within K55
    finally:
        m.close()
    connect("coolmuscle://?mode=fast", timeout=float("inf")).close()


def test_a_lone_wait_on_a_fast_port_takes_no_wall_time() -> None:
    """docs/user-guide.md: on ``mode=fast`` "a 5 s wait takes no wall time"; a wait with
    no other thread about does not stop between its reads to make way."""
    import time

    from coolmuscle.errors import CoolMuscleTimeout

    m = connect("coolmuscle://?mode=fast")
    try:
        start = time.monotonic()
        with pytest.raises(CoolMuscleTimeout):
            m.wait_event(kind="input", timeout=1000)      # 4,000 read slices of 0.25 s
        assert m.port.kernel.now == 1000 * 10 ** 9
        assert time.monotonic() - start < 2.0           # slices without pauses (~0.02 s)
    finally:
        m.close()

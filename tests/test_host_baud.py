"""A host at another baud rate than K20 (ch. 3 K20), or another frame than the motor's
(8 data bits, K82 parity, 1 stop bit; 5.6.1): garbage both ways, with pacing.

The UART model (coolmuscle.device.uart, docs/fidelity.md "Baud rate of the host") is
checked on frames worked out by hand; the host line garbles a host's bytes and what that
host reads only while pacing is on and its port's rate (or frame, when the port says it)
differs from the motor's; K82 frames the motor's bytes with a parity bit (11 bits on the
wire); a pty client that sets its port to another rate than the motor gets no answer,
and gets one again at the right rate.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest
import serial

from coolmuscle.chain.daisy import Chain
from coolmuscle.device.hostline import byte_time_ns
from coolmuscle.device.uart import Frame, as_read_at
from coolmuscle.frontends.transports.pty import PtyTransport, client_baud
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.sim.kernel import seconds

RATES = (9600, 19200, 38400, 57600, 115200, 230400)


# -- the UART model ------------------------------------------------------------------

def test_equal_rates_read_the_bytes_sent() -> None:
    data = bytes(range(256))
    assert all(as_read_at(data, rate, rate) == data for rate in RATES)


def test_a_reader_twice_as_fast_reads_each_half_of_a_frame_as_a_byte() -> None:
    # 0x0F at 9600: start, 1111, 0000, stop; each sent bit is two read bits.  The first
    # frame read: start, then 0 (the start's second half) and seven 1s -> 0xFE; the
    # second starts at the four 0s: seven 0s and the stop's 1 -> 0x80; both stops high.
    assert as_read_at(b"\x0f", 9600, 19200) == b"\xfe\x80"


def test_a_stop_bit_read_low_is_a_framing_error_read_as_zero() -> None:
    # 0x00 at 9600 is low for nine bits, 36 bits at 38400: three frames of zeros whose
    # stop bit is still low (framing errors, read as 0x00, termios(3) IGNPAR), then one
    # that ends in the sent stop bit.
    assert as_read_at(b"\x00", 9600, 38400) == b"\x00\x00\x00\xc0"


def test_a_reader_slower_than_the_sender_reads_fewer_bytes() -> None:
    text = b"ID1 : CM2v3.10R.1 #0802A12345\r\n"
    for sent in RATES:
        for read in RATES:
            if read < sent:
                assert len(as_read_at(text, sent, read)) < len(text)


def test_garbage_never_reads_as_the_text_sent() -> None:
    text = b"?85.1\r"
    for sent in RATES:
        for read in RATES:
            if sent != read:
                assert text not in as_read_at(text, sent, read)


def test_a_parity_bit_read_as_the_stop_bit_is_a_framing_error() -> None:
    # 8E1 read as 8N1 at one rate: 0x01 (one 1: parity 1) has its parity bit where the
    # reader samples the stop bit, high: read right; 0x03 (two 1s: parity 0) low there:
    # a framing error, 0x00; the reader then finds the stop bit high (no false start)
    assert as_read_at(b"\x01\x03", 38400, 38400, Frame(parity="E"), Frame()) == b"\x01\x00"


def test_a_reader_with_parity_checks_the_stop_bit_sent_as_parity() -> None:
    # 8N1 read as 8E1: the stop bit (1) is read as the parity bit, the idle line as stop
    assert as_read_at(b"\x01", 38400, 38400, Frame(), Frame(parity="E")) == b"\x01"
    assert as_read_at(b"\x03", 38400, 38400, Frame(), Frame(parity="E")) == b"\x00"
    assert as_read_at(b"\x03", 38400, 38400, Frame(), Frame(parity="M")) == b"\x03"
    assert as_read_at(b"\x03", 38400, 38400, Frame(), Frame(parity="S")) == b"\x00"
    assert as_read_at(b"\x03", 38400, 38400, Frame(parity="O"), Frame(parity="O")) == b"\x03"


def test_seven_data_bits_read_an_eighth_bit_as_the_stop_bit() -> None:
    # 8N1 read as 7N1: bit 7 is sampled as the stop bit
    assert as_read_at(b"\x41", 9600, 9600, Frame(), Frame(7)) == b"\x00"
    assert as_read_at(b"\xc1", 9600, 9600, Frame(), Frame(7)) == b"\x41"
    assert as_read_at(b"\xc1", 9600, 9600, Frame(7), Frame(7)) == b"\x41"
    assert as_read_at(b"\xc1", 9600, 9600, Frame(7, "N", 2), Frame(7)) == b"\x41"


def test_a_frame_a_uart_cannot_take_is_refused() -> None:
    for bad in ((9, "N", 1), (8, "X", 1), (8, "N", 3)):
        with pytest.raises(ValueError):
            Frame(*bad)


def test_a_parity_bit_makes_a_byte_eleven_bits_long() -> None:
    assert byte_time_ns(38400, Frame(parity="E")) == 11 * 10**9 // 38400
    assert byte_time_ns(38400, Frame(7, "N", 1.5)) == int(9.5 * 10**9) // 38400
    chain = Chain(pacing=True)
    chain.execute("K82.1=1")                         # ch. 3 K82: even parity
    arrived: list[int] = []
    chain.host_line.add_listener(lambda data: arrived.append(chain.kernel.now))
    start = chain.kernel.now
    chain.host_line.write(b"ab")
    chain.kernel.run(until=seconds(0.1))
    assert arrived == [start + 2 * (11 * 10**9 // 38400)]
    chain.close()


# -- the host line -------------------------------------------------------------------

def _chain_with_host(baud: list[int]) -> tuple[Chain, object, list[bytes], list[bytes]]:
    """A paced chain; a host whose port rate is ``baud[0]`` (changeable), what it reads,
    and what a second listener without a known rate (a TCP client) reads."""
    chain = Chain(pacing=True)
    host = object()
    chain.host_line.set_host_baud(host, lambda: baud[0])
    heard: list[bytes] = []
    plain: list[bytes] = []
    chain.host_line.add_listener(heard.append, host)
    chain.host_line.add_listener(plain.append)
    return chain, host, heard, plain


def test_a_matched_host_is_answered_as_before() -> None:
    baud = [38400]
    chain, host, heard, plain = _chain_with_host(baud)
    chain.host_line.feed(b"?96.1\r", host)
    chain.kernel.run(until=seconds(0.1))
    assert b"".join(heard) == b"".join(plain) == b"?96.1\r\nPx.1=0\r\n"
    chain.close()


def test_a_host_at_another_rate_sends_garbage_and_reads_garbage() -> None:
    baud = [9600]
    chain, host, heard, plain = _chain_with_host(baud)
    chain.host_line.feed(b"?96.1\r", host)
    chain.kernel.run(until=seconds(0.1))
    echo = b"".join(plain)                 # the motor echoes what it read: garbage
    assert echo and b"Px.1" not in echo and b"?96.1" not in echo
    assert b"".join(heard) == as_read_at(echo, 38400, 9600)
    baud[0] = 38400                         # the host sets its port right: answered
    heard.clear()
    chain.host_line.feed(b"\r?96.1\r", host)
    chain.kernel.run(until=seconds(0.2))
    assert b"".join(heard).endswith(b"?96.1\r\nPx.1=0\r\n")
    chain.close()


def test_a_host_follows_a_k20_change_to_be_answered() -> None:
    baud = [38400]
    chain, host, heard, _plain = _chain_with_host(baud)
    chain.host_line.feed(b"K20.1=2\r", host)         # K23 without 16: at once (ch. 3 K20)
    chain.kernel.run(until=seconds(0.1))
    assert chain.get_param(1, 20) == 2
    heard.clear()
    chain.host_line.feed(b"\r?96.1\r", host)
    chain.kernel.run(until=seconds(0.2))
    assert b"Px.1=0" not in b"".join(heard)
    baud[0] = 19200
    heard.clear()
    chain.host_line.feed(b"\r?96.1\r", host)
    chain.kernel.run(until=seconds(0.3))
    assert b"".join(heard).endswith(b"?96.1\r\nPx.1=0\r\n")
    chain.close()


def test_a_port_set_beyond_any_uart_reads_as_at_the_fastest_one() -> None:
    """A pty client may set any number (Linux BOTHER): the line takes the host's rate
    within 50 bit/s .. 12 Mbit/s, so a port at 4 Gbit/s reads what one at 12 Mbit/s
    reads (garbage either way) and the model is not held up reading it."""
    chain, _host, heard, plain = _chain_with_host([0xFFFFFFFF])
    chain.host_line.feed(b"?96.1\r")                 # from a client of no known rate
    chain.kernel.run(until=seconds(0.1))
    assert plain and heard == [as_read_at(chunk, 38400, 12_000_000) for chunk in plain]
    chain.close()


def test_k82_frames_the_motors_bytes_a_host_must_match() -> None:
    chain = Chain(pacing=True)
    chain.execute("K82.1=2")                         # ch. 3 K82: odd parity
    frame = [Frame()]
    host = object()
    chain.host_line.set_host_baud(host, lambda: 38400)
    chain.host_line.set_host_frame(host, lambda: frame[0])
    heard: list[bytes] = []
    plain: list[bytes] = []
    chain.host_line.add_listener(heard.append, host)
    chain.host_line.add_listener(plain.append)
    chain.host_line.feed(b"?96.1\r", host)
    chain.kernel.run(until=seconds(0.1))
    assert b"Px.1" not in b"".join(plain)            # the motor read garbage
    assert heard == [as_read_at(chunk, 38400, 38400, Frame(parity="O"), Frame())
                     for chunk in plain]
    frame[0] = Frame(parity="O")                     # the host sets its port to 8O1
    heard.clear()
    chain.host_line.feed(b"\r?96.1\r", host)
    chain.kernel.run(until=seconds(0.2))
    assert b"".join(heard).endswith(b"?96.1\r\nPx.1=0\r\n")
    chain.close()


def test_a_host_that_does_not_say_its_frame_is_taken_as_matched() -> None:
    chain = Chain(pacing=True)
    chain.execute("K82.1=1")
    host = object()
    chain.host_line.set_host_baud(host, lambda: 38400)    # a pty: the rate, no frame
    heard: list[bytes] = []
    chain.host_line.add_listener(heard.append, host)
    chain.host_line.feed(b"?96.1\r", host)
    chain.kernel.run(until=seconds(0.1))
    assert b"".join(heard) == b"?96.1\r\nPx.1=0\r\n"
    chain.close()


def test_without_pacing_the_host_rate_has_no_effect() -> None:
    chain = Chain()
    chain.host_line.set_host_baud(None, lambda: 9600)
    heard: list[bytes] = []
    chain.host_line.add_listener(heard.append, None)
    chain.host_line.feed(b"?96.1\r")
    assert b"".join(heard) == b"?96.1\r\nPx.1=0\r\n"
    chain.close()


# -- the pty: the rate the client set ------------------------------------------------------

@pytest.fixture
def paced_pty() -> Iterator[str]:
    st_ = ServiceThread(lambda: Chain(pacing=True), lambda: [PtyTransport()]).start()
    try:
        yield str(st_.transports[0].info()["path"])
    finally:
        st_.stop()


def _ask(port: serial.Serial, text: bytes) -> bytes:
    port.reset_input_buffer()
    port.write(text)
    time.sleep(0.15)
    return port.read(port.in_waiting or 1)


def test_the_pty_tells_the_line_the_rate_the_client_set(paced_pty: str) -> None:
    with serial.Serial(paced_pty, baudrate=9600, timeout=0.2) as port:
        assert client_baud(port.fileno()) == 9600
        assert b"Px.1=" not in _ask(port, b"?96.1\r")
        port.baudrate = 38400
        assert _ask(port, b"\r?96.1\r").endswith(b"?96.1\r\nPx.1=0\r\n")
        port.baudrate = 12345                 # a rate set by number (Linux BOTHER)
        assert client_baud(port.fileno()) == 12345
        assert b"Px.1=" not in _ask(port, b"?96.1\r")

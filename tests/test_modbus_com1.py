"""COM1 as a Modbus host: the messages of 5.6.7 FC01/02/05/15 generated from CML, byte for byte.

The slave device is "final motor ID + 1" (5.6.6 setting example 3).  In virtual
time the test plays the slave: it takes the frames COM1 sends and feeds answers
built with the independent CRC of tests/modbus_support.py.
"""

from __future__ import annotations

import pytest

from coolmuscle.chain.firmware_modbus.master import RESPONSE_TIMEOUT_NS
from coolmuscle.sim.kernel import ms
from modbus_support import Wire, frame


class Com1Wire(Wire):
    """A chain whose COM1 wire is visible: ``sent`` holds the frames COM1 sent."""

    def __init__(self, motors: int = 3, **params: int) -> None:
        super().__init__(motors, **{f"K84_{motors}": 1, **params})
        self.sent: list[bytes] = []
        self.chain.com1.add_listener(self.sent.append)

    def answer(self, data: bytes) -> None:
        self.chain.com1.feed(data)

    def ask(self, line: str, answer: bytes | None = None) -> str:
        """Type ``line`` on the host line; answer COM1's message; return the host line text."""
        self.out.clear()
        self.send(line.encode() + b"\r")
        self.idle(ms(1))
        if answer is not None:
            self.answer(answer)
        self.idle(ms(5))
        text = self.out.decode("latin-1")
        self.out.clear()
        return text


#: 5.6.7 parameter settings on the final motor (ID3; the slave is ID4).
MANUAL = {"K79_3": 200, "K80_3": 300, "K81_3": 1}


def test_5_6_7_fc01_generated_from_query_50() -> None:
    wire = Com1Wire(**MANUAL)
    text = wire.ask("?50.4", frame("01 01 02 CD 01"))
    assert wire.sent == [frame("01 01 01 2C 00 10")]
    assert text == "?50.4\r\nOUT.4=CD01\r\n"


def test_5_6_7_fc02_generated_from_query_70() -> None:
    wire = Com1Wire(**MANUAL)
    wire.ask("?70.4", frame("01 02 02 1A 04"))
    assert wire.sent == [frame("01 02 00 C8 00 10")]


def test_5_6_6_setting_example_3_query_70_replies_in_hex() -> None:
    """Setting example 3: K81=0 everywhere, K84=1 on ID3; ``?70.4`` -> ``IN.4=1A04``."""
    wire = Com1Wire()
    assert wire.chain.get_param(3, 81) == 0 and wire.chain.get_param(3, 79) == 0
    text = wire.ask("?70.4", frame("01 02 02 1A 04"))
    assert wire.sent == [frame("01 02 00 00 00 10")]
    assert text == "?70.4\r\nIN.4=1A04\r\n"


def test_5_6_7_fc05_generated_from_o7_and_f7() -> None:
    """The text: "206 (0xCE) ... the 7th address from 200 (set value of K80)"."""
    wire = Com1Wire(K80_3=200)
    assert wire.ask("O7.4", frame("01 05 00 CE FF 00")) == "O7.4\r\n"
    assert wire.ask("F7.4", frame("01 05 00 CE 00 00")) == "F7.4\r\n"
    assert wire.sent == [frame("01 05 00 CE FF 00"), frame("01 05 00 CE 00 00")]
    assert wire.chain.com1.answered == 2


def test_5_6_7_fc05_with_the_parameter_table_k80_300() -> None:
    wire = Com1Wire(**MANUAL)
    wire.ask("O7.4", frame("01 05 01 32 FF 00"))
    wire.ask("O1.4", frame("01 05 01 2C FF 00"))
    assert wire.sent == [frame("01 05 01 32 FF 00"), frame("01 05 01 2C FF 00")]


def test_5_6_7_fc15_generated_from_o_4_52481() -> None:
    """The table prints function code 0x05; the heading and Modbus say 15 (0x0F)."""
    wire = Com1Wire(**MANUAL)
    wire.ask("O.4=52481", frame("01 0F 01 2C 00 10"))
    assert wire.sent == [frame("01 0F 01 2C 00 10 02 CD 01")]
    assert wire.chain.com1.answered == 1


def test_k85_com1_little_endian_sends_the_low_byte_first() -> None:
    wire = Com1Wire(**MANUAL, K85_3=2)
    wire.ask("O.4=52481", frame("01 0F 01 2C 00 10"))
    text = wire.ask("?70.4", frame("01 02 02 1A 04"))
    assert wire.sent[0] == frame("01 0F 01 2C 00 10 02 01 CD")
    assert text.endswith("IN.4=041A\r\n")


def test_com1_answers_to_the_api_arrive_as_events() -> None:
    wire = Com1Wire(**MANUAL)
    assert wire.chain.execute("?70.4") == []
    wire.answer(frame("01 02 02 00 21"))
    replies = [e for e in wire.events if e.kind == "reply"]
    assert [(r.motor, r.text, r.value, r.origin) for r in replies] == [(4, "IN.4=0021", 0x21,
                                                                          "api")]
    assert wire.out == b""


def test_com1_no_answer_exception_or_bad_crc_prints_nothing() -> None:
    wire = Com1Wire(**MANUAL)
    com1 = wire.chain.com1
    assert wire.ask("?70.4") == "?70.4\r\n"
    wire.idle(RESPONSE_TIMEOUT_NS)
    assert com1.timeouts == 1
    assert wire.ask("?70.4", frame("01 82 02")) == "?70.4\r\n"
    bad = frame("01 02 02 1A 04")
    assert wire.ask("?70.4", bad[:-1] + b"\x00") == "?70.4\r\n"
    assert (com1.exceptions, com1.errors) == (1, 1)
    assert wire.ask("?70.4", frame("01 02 02 1A 04")) == "?70.4\r\nIN.4=1A04\r\n"


def test_com1_one_message_at_a_time_with_the_silent_interval_between() -> None:
    wire = Com1Wire(**MANUAL)
    wire.send(b"?70.4, ?50.4, O3.4\r")
    wire.idle(ms(1))
    assert len(wire.sent) == 1
    wire.answer(frame("01 02 02 00 01"))
    wire.idle(ms(1))    # 5.6.2 interval at 38.4 kbps is 1.67 ms
    assert len(wire.sent) == 1
    wire.idle(ms(1))
    assert wire.sent[1] == frame("01 01 01 2C 00 10")
    wire.answer(frame("01 01 02 00 00"))
    wire.idle(ms(3))
    assert wire.sent[2] == frame("01 05 01 2E FF 00")


def test_com1_answer_split_by_a_long_pause_is_illegal() -> None:
    wire = Com1Wire(**MANUAL)
    answer = frame("01 02 02 1A 04")
    wire.send(b"?70.4\r")
    wire.idle(ms(1))
    wire.answer(answer[:3])
    wire.idle(ms(2))
    wire.answer(answer[3:])
    wire.idle(ms(1))
    assert b"IN.4" not in wire.out
    wire.idle(RESPONSE_TIMEOUT_NS)
    assert wire.chain.com1.timeouts == 1


def test_statements_for_the_slave_need_k84_1_on_the_final_motor() -> None:
    wire = Com1Wire(**MANUAL)
    wire.chain.set_param(3, 84, 0)
    assert wire.ask("?70.4") == "?70.4\r\n" and wire.sent == []
    wire.chain.set_param(2, 84, 1)          # not the final motor: its COM1 is the chain
    assert wire.ask("?70.4") == "?70.4\r\n" and wire.sent == []
    wire.chain.set_param(3, 84, 1)
    assert wire.ask("?70.5") == "?70.5\r\n" and wire.sent == []   # final + 2 is nobody


@pytest.mark.parametrize("line", ["O17.4", "O0.4", "O.4=65536", "O.4=-1"])
def test_com1_outputs_beyond_16_bits_are_out_of_range(line: str) -> None:
    wire = Com1Wire(**MANUAL, K23_3=17)
    assert wire.ask(line) == f"{line}\r\nerror00.4: Out Of Range!!\r\n"
    assert wire.sent == []


def test_k79_minus_1_sends_no_input_query() -> None:
    wire = Com1Wire(K79_3=-1)
    assert wire.ask("?70.4") == "?70.4\r\n" and wire.sent == []

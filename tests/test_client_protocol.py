"""The sans-IO core of the host library: line ends, echo, exchanges, events, 6.6 replies."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from coolmuscle.client.ops import named
from coolmuscle.client.protocol import Exchange, LineSplitter, Protocol
from coolmuscle.client.replies import classify, parse_io_word, parse_listing, parse_version
from coolmuscle.errors import CmlSyntaxError, OutOfRangeError, ProtocolError, TooManyStepsError


def px(motor: int = 1) -> Exchange:
    return Exchange((f"?96.{motor}",), named("Px", motor), motor, "Px reply")


# -- line ends (ch. 3 K70) -------------------------------------------------------------

@pytest.mark.parametrize("data, delimiter", [
    (b"Px.1=5\r\nUx.1=8\r\n", b"\r\n"), (b"Px.1=5\rUx.1=8\r", b"\r"),
    (b"Px.1=5\nUx.1=8\n", b"\n")])
def test_each_line_end_is_learned(data: bytes, delimiter: bytes) -> None:
    split = LineSplitter()
    assert split.feed(data) == [b"Px.1=5", b"Ux.1=8"]
    assert split.delimiter == delimiter


def test_a_crlf_split_across_reads_makes_one_line_end() -> None:
    split = LineSplitter()
    assert split.feed(b"Px.1=5\r") == [b"Px.1=5"]
    assert split.feed(b"\nUx.1=") == []
    assert split.feed(b"8\r\n") == [b"Ux.1=8"]
    assert split.delimiter == b"\r\n"


@given(st.binary(max_size=300), st.lists(st.integers(1, 50), max_size=10))
@settings(max_examples=200, deadline=None)
def test_splitting_does_not_depend_on_how_bytes_arrive(data: bytes, cuts: list[int]) -> None:
    whole = LineSplitter().feed(data)
    split, pieces, start = LineSplitter(), [], 0
    for cut in cuts:
        pieces += split.feed(data[start:start + cut])
        start += cut
    pieces += split.feed(data[start:])
    assert pieces == whole


# -- echo (ch. 3 K23 function 8) -----------------------------------------------------------

def test_echo_on_is_learned_and_the_echo_is_not_an_answer() -> None:
    proto = Protocol()
    ex = px()
    assert proto.begin(ex) == b"?96.1\r"
    assert proto.receive(b"?96.1\r\nPx.1=10000\r\n") == []
    assert ex.complete and [l.text for l in ex.lines] == ["Px.1=10000"]
    assert proto.echo is True and proto.delimiter == b"\r\n"


def test_echo_off_is_learned_from_an_answer_without_echo() -> None:
    proto = Protocol()
    ex = px()
    proto.begin(ex)
    proto.receive(b"Px.1=3\r")
    assert ex.complete and proto.echo is False and proto.delimiter is None
    proto.receive(b"\n")
    assert proto.delimiter == b"\r\n"


def test_echo_switched_off_by_the_exchange_itself() -> None:
    """``K23.1=9`` is still echoed; the fence after it is not (K23 takes effect at once)."""
    proto = Protocol()
    proto.echo = True
    ex = Exchange(("K23.1=9", "?96.1"), named("Px", 1), 1)
    proto.begin(ex)
    proto.receive(b"K23.1=9\r\nPx.1=0\r\n")
    assert ex.complete and proto.echo is False


def test_echo_switched_back_on_is_noticed() -> None:
    proto = Protocol()
    proto.echo = False
    ex = px()
    proto.begin(ex)
    proto.receive(b"?96.1\r\nPx.1=1\r\n")
    assert ex.complete and proto.echo is True


def test_with_echo_on_lines_before_the_echo_are_not_the_answer() -> None:
    """A stale reply (from a request that timed out) is an event, not this answer."""
    proto = Protocol()
    proto.echo = True
    ex = px()
    proto.begin(ex)
    events = proto.receive(b"Px.1=111\r\nUx.1=8\r\n?96.1\r\nPx.1=222\r\n")
    assert [l.text for l in ex.lines] == ["Px.1=222"]
    assert [(e.kind, e.text) for e in events] == [("unsolicited", "Px.1=111"),
                                                  ("status", "Ux.1=8")]


def test_a_timed_out_exchange_makes_echo_unknown_again() -> None:
    proto = Protocol()
    proto.echo = True
    proto.begin(px())
    proto.abandon()
    assert proto.echo is None and proto.exchange is None


def test_a_damaged_echo_counts_as_the_echo() -> None:
    """A garbled line where the echo should be: the answer after it is still taken."""
    proto = Protocol()
    proto.echo = True
    ex = px()
    proto.begin(ex)
    events = proto.receive(b"?9\xff.1\r\nPx.1=7\r\n")
    assert ex.complete and ex.lines[-1].text == "Px.1=7"
    assert [e.kind for e in events] == ["garbled"] and ex.garbled == ["?9\xff.1"]


# -- exchanges: errors, reports, multi-line answers ------------------------------------------

def test_errors_of_the_addressed_motor_are_collected_in_order() -> None:
    proto = Protocol()
    ex = Exchange(("hello", "?96.1"), named("Px", 1), 1)
    proto.begin(ex)
    proto.receive(b"hello\r\nerror01.1: syntax error!!\r\n?96.1\r\nPx.1=0\r\n")
    assert ex.complete
    assert len(ex.errors) == 1 and isinstance(ex.errors[0], CmlSyntaxError)
    assert ex.errors[0].number == 1 and ex.errors[0].motor == 1  # type: ignore[attr-defined]


def test_errors_of_another_motor_are_events() -> None:
    proto = Protocol()
    ex = px()
    proto.begin(ex)
    events = proto.receive(b"?96.1\r\nerror02.2: too many steps!!\r\nPx.1=0\r\n")
    assert ex.errors == [] and [e.kind for e in events] == ["error"]
    assert events[0].value == 2 and events[0].motor == 2


def test_reports_during_an_exchange_are_events_and_the_status_reply_completes() -> None:
    proto = Protocol()
    ex = Exchange(("^.1", "?99.1"), lambda l: l.kind == "status" and l.motor == 1, 1)
    proto.begin(ex)
    events = proto.receive(b"^.1\r\n?99.1\r\nIN.1=04\r\nUx.1=0\r\nUx.1=8\r\n")
    assert ex.lines[-1].text == "Ux.1=0"
    assert [(e.kind, e.value) for e in events] == [("input", 4), ("status", 8)]
    assert proto.status_seen[1] == (events[-1].seq, 8)


def test_a_report_between_the_command_and_the_fence_does_not_complete_it() -> None:
    """``*`` reports ``Ux.1=512`` at once; the ``?99`` fence's reply comes after its echo."""
    proto = Protocol()
    proto.echo = True
    ex = Exchange(("*", "?99.1"), lambda l: l.kind == "status" and l.motor == 1, 1)
    proto.begin(ex)
    events = proto.receive(b"*\r\nUx.1=512\r\n")
    assert not ex.complete and [e.text for e in events] == ["Ux.1=512"]
    proto.receive(b"?99.1\r\nUx.1=512\r\n")
    assert ex.complete and [l.text for l in ex.lines] == ["Ux.1=512"]


def test_a_query_s_reply_between_echoes_is_an_answer_not_a_report() -> None:
    proto = Protocol()
    proto.echo = True
    ex = Exchange(("?50.1", "?96.1"), named("Px", 1), 1)
    proto.begin(ex)
    events = proto.receive(b"?50.1\r\nOUT.1=03\r\n?96.1\r\nPx.1=0\r\n")
    assert events == [] and [l.text for l in ex.lines] == ["OUT.1=03", "Px.1=0"]


def test_the_late_echo_of_an_earlier_exchange_is_not_this_one_s() -> None:
    """Two exchanges send the same fence; the first one's late echo and reply must not
    complete the second (it timed out and was abandoned)."""
    proto = Protocol()
    proto.echo = True
    first = Exchange(("*", "?99.1"), lambda l: l.kind == "status", 1)
    proto.begin(first)
    proto.receive(b"*\r\n")
    proto.abandon()
    second = Exchange(("*1", "?99.1"), lambda l: l.kind == "status", 1)
    proto.begin(second)
    proto.receive(b"?99.1\r\nUx.1=512\r\n")        # the first exchange's late answer
    assert not second.complete
    proto.receive(b"*1\r\n?99.1\r\nUx.1=8\r\n")
    assert second.complete and second.lines[-1].text == "Ux.1=8"


def test_a_multi_line_answer_keeps_its_lines() -> None:
    proto = Protocol()
    ex = Exchange(("?90.1", "?96.1"), named("Px", 1), 1)
    proto.begin(ex)
    proto.receive(b"?90.1\r\nK20.1=0, K21.1=0, K22.1=200, K23.1=1\r\n"
                  b"K88.1=0, K89.1=0\r\n?96.1\r\nPx.1=0\r\n")
    texts = [l.text for l in ex.lines]
    assert texts[:-1] == ["K20.1=0, K21.1=0, K22.1=200, K23.1=1", "K88.1=0, K89.1=0"]
    items = parse_listing(texts[:-1])
    assert items["K22"] == "200" and items["K89"] == "0"


def test_until_echo_exchanges_complete_at_their_echo() -> None:
    proto = Protocol()
    proto.echo = True
    ex = Exchange(("S1.1, A1.1, P1.1",), lambda _l: False, 1, until_echo=True)
    proto.begin(ex)
    proto.receive(b"S1.1, A1.1, P1.1\r\n")
    assert ex.complete and ex.end_seq == proto.seq


def test_lines_sent_must_not_hold_line_ends() -> None:
    with pytest.raises(ValueError):
        Protocol().encode(["P.1=5\r^.1"])


@given(st.binary(max_size=400))
@settings(max_examples=300, deadline=None)
def test_any_bytes_never_break_the_core(data: bytes) -> None:
    proto = Protocol()
    ex = px()
    proto.begin(ex)
    for event in proto.receive(data):
        assert event.seq <= proto.seq
    assert isinstance(ex.complete, bool)


# -- the 6.6 reply forms ----------------------------------------------------------------

@pytest.mark.parametrize("text, kind, motor, name, value", [
    ("Px.1=10000", "value", 1, "Px", "10000"),
    ("Ux.2=8", "status", 2, "Ux", "8"),
    ("IN.1=1C", "input", 1, "IN", "1C"),
    ("OUT.1=03", "output", 1, "OUT", "03"),
    ("OUT2.1=0", "value", 1, "OUT2", "0"),
    ("K23.1=17", "value", 1, "K23", "17"),
    ('V1.1="abcd"', "value", 1, "V1", '"abcd"'),
    ("error00.3: Out Of Range!!", "error", 3, "error00", "Out Of Range!!"),
    ("saved.1", "message", 1, None, None),
    ("End.2", "message", 2, None, None),
    ("[End of Bank]", "message", None, None, None),
    ("ID1 : CM2v3.10R.1 #0802A12345", "version", 1, None, None),
    ("P.1=10000, S.1=100, A.1=100, M.1=100", "listing", 1, None, None),
    ("S1.1, A1.1, P1.1", "text", None, None, None),
    ("Px.1=\x00", "garbled", None, None, None),
])
def test_classify(text: str, kind: str, motor: int | None, name: str | None,
                  value: str | None) -> None:
    line = classify(text.encode("latin-1"))
    assert (line.kind, line.motor, line.name, line.value) == (kind, motor, name, value)


def test_error_lines_become_the_matching_exceptions() -> None:
    assert isinstance(classify(b"error00.1: Out Of Range!!").error(), OutOfRangeError)
    assert isinstance(classify(b"error02.1: too many steps!!").error(), TooManyStepsError)
    unknown = classify(b"error42.1: what").error()
    assert unknown.number == 42 and "error42.1: what" in str(unknown)


def test_garbled_values_raise_protocol_errors() -> None:
    with pytest.raises(ProtocolError, match="garbled"):
        classify(b"Px.1=12a4").int_value()
    with pytest.raises(ProtocolError):
        parse_io_word(classify(b"IN.1=zz"))
    with pytest.raises(ProtocolError):
        parse_version("ID1 CM2")


def test_version_title_fields_and_profile() -> None:
    version = parse_version("ID1 : CM2v3.10R.1 #0802A12345")
    assert (version.motor, version.series, version.firmware, version.motor_type,
            version.hardware, version.serial) == (1, "CM2", "3.10", "R", "1", "0802A12345")
    assert version.profile() == "cm2"
    assert parse_version("ID2 : CM1v3.00C.1 #0000A00000").profile() == "cm1"
    assert parse_version("ID2 : CM1v3.00R.1 #0000A00000").profile() == "rt3"


def test_an_exchange_gets_its_own_echoes_after_one_of_the_same_text_lost_them() -> None:
    """A dead line (docs/wire-faults.md) loses the lines and so their echoes: the same
    lines sent again are echoed for the new exchange, not credited to the abandoned one
    (which would leave this and every later exchange one echo behind)."""
    proto = Protocol()
    proto.echo = True
    first = Exchange(("P1.1", "?96.1"), named("Px", 1), 1)
    proto.begin(first)
    proto.abandon()                                   # nothing came back
    second = Exchange(("P1.1", "?96.1"), named("Px", 1), 1)
    proto.begin(second)
    proto.receive(b"P1.1\r\nP1.1=0\r\n?96.1\r\nPx.1=0\r\n")
    assert second.complete and [line.text for line in second.lines] == ["P1.1=0", "Px.1=0"]
    third = Exchange(("P1.1", "?96.1"), named("Px", 1), 1)
    proto.begin(third)
    proto.receive(b"P1.1\r\nP1.1=5\r\n?96.1\r\nPx.1=0\r\n")
    assert third.complete and third.lines[0].text == "P1.1=5"

"""The script / golden transcript format and runner (docs/scripts.md)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from coolmuscle.device.hostline import byte_time_ns
from coolmuscle.sim.kernel import seconds
from coolmuscle.tools.script.runner import (
    DEFAULT_UNTIL_TIMEOUT,
    ScriptError,
    TranscriptEntry,
    escape,
    load_script,
    parse_script,
    run_script,
    split_lines,
    unescape,
)
from fakes import ROUNDTRIP, FakeChain
from fixtures import ROOT, ChainFactory


# -- format ---------------------------------------------------------------
def test_line_kinds() -> None:
    script = parse_script("# comment\n#\n#2.1\nS.1=100\n\n@wait 1.5\n@send ?96.1\\r\n"
                          "@until Ux\\.1=8 3\n<< Ux.1=8\\r\\n\n@.1+\n<.1\n#\tx\n")
    kinds = [(s.kind, s.data) for s in script.lines]
    assert kinds == [("comment", b""), ("comment", b""), ("send", b"#2.1\r"),
                     ("send", b"S.1=100\r"), ("send", b"\r"), ("wait", b""),
                     ("raw", b"?96.1\r"), ("until", b""), ("expect", b"Ux.1=8\r\n"),
                     ("send", b"@.1+\r"), ("send", b"<.1\r"), ("send", b"#\tx\r")]
    assert script.lines[5].seconds == 1.5
    until = script.lines[7]
    assert until.seconds == 3 and until.pattern is not None and until.pattern.pattern == r"Ux\.1=8"
    assert script.expectations == 1 and len(script.steps) == 10


def test_file_line_endings_and_final_newline() -> None:
    assert [s.data for s in parse_script("A\r\nB\r\n").steps] == [b"A\r", b"B\r"]
    assert [s.data for s in parse_script("A\n\n").steps] == [b"A\r", b"\r"]
    assert [s.data for s in parse_script("A").steps] == [b"A\r"]


def test_plain_lines_are_sent_exactly_as_typed() -> None:
    assert parse_script("  S.1=100  \\r\n").steps[0].data == b"  S.1=100  \\r\r"


def test_until_default_timeout_and_spaces_in_the_pattern() -> None:
    step = parse_script("@until Ux.1=8").steps[0]
    assert step.seconds == DEFAULT_UNTIL_TIMEOUT
    step = parse_script("@until End of Bank 2.5").steps[0]
    assert step.pattern is not None
    assert step.pattern.pattern == "End of Bank" and step.seconds == 2.5
    step = parse_script("@until Px.1=100").steps[0]
    assert step.pattern is not None and step.pattern.pattern == "Px.1=100"


@pytest.mark.parametrize("text, message", [
    ("@frobnicate", "line 1: unknown directive @frobnicate"),
    ("ok\n@wait", "line 2: @wait"),
    ("@wait -1", "seconds must be 0..1e.09, not -1"),
    ("@wait soon", "is not a number"),
    ("@until", "needs a regular expression"),
    ("@until Ux(", "bad regular expression"),
    ("@send", "@send needs bytes"),
    ("@send \\q", "bad escape"),
    ("<<", "an expectation is '<< '"),
    ("<<Ux", "an expectation is '<< '"),
    ("<< \\x4", "bad escape"),
    ("S.1=\u20ac", "not bytes"),
])
def test_bad_lines_are_reported_with_their_number(text: str, message: str) -> None:
    with pytest.raises(ScriptError, match=message.replace("(", r"\(")):
        parse_script(text)


def test_escapes() -> None:
    assert unescape(r"a\r\n\t\0\e\\\x7f\xFF") == b"a\r\n\t\x00\x1b\\\x7f\xff"
    assert escape(b"a\r\n\t\x00\\\xff") == r"a\r\n\t\x00\\\xff"


@given(st.binary())
def test_escape_round_trip(data: bytes) -> None:
    assert unescape(escape(data)) == data


def _escape_byte(byte: int) -> str:
    names = {92: "\\\\", 13: "\\r", 10: "\\n", 9: "\\t"}
    if byte in names:
        return names[byte]
    return chr(byte) if 32 <= byte < 127 else f"\\x{byte:02x}"


@given(st.binary() | st.text(st.characters(min_codepoint=32, max_codepoint=126)).map(str.encode))
def test_escape_is_byte_by_byte_on_every_path(data: bytes) -> None:
    """The transcript's fast path (printable ASCII shown as is) and the byte loop agree."""
    assert escape(data) == "".join(_escape_byte(b) for b in data)


def _unescape_byte_by_byte(text: str) -> bytes:
    """The reading of docs/scripts.md "Escapes", one character at a time: the reference
    the table-driven :func:`unescape` must agree with (result and first error)."""
    names = {"r": 13, "n": 10, "t": 9, "0": 0, "e": 27, "\\": 92}
    out, i = bytearray(), 0
    while i < len(text):
        if text[i] != "\\":
            if ord(text[i]) > 0xFF:
                raise ValueError(f"character {text[i]!r} is not a byte (use \\xNN)")
            out.append(ord(text[i]))
            i += 1
        elif text[i + 1:i + 2] in names and text[i + 1:i + 2]:
            out.append(names[text[i + 1]])
            i += 2
        elif text[i + 1:i + 2] == "x" and re.fullmatch(r"[0-9A-Fa-f]{2}", text[i + 2:i + 4]):
            out.append(int(text[i + 2:i + 4], 16))
            i += 4
        else:
            raise ValueError(f"bad escape {text[i:i + 4]!r} (use \\r \\n \\t \\0 \\e "
                             "\\\\ \\xNN)")
    return bytes(out)


@given(st.lists(st.sampled_from(["a", "\\", "x", "4", "F", "r", "e", "q", "\n", "\u20ac",
                                 "\xff", " "])).map("".join))
def test_unescape_agrees_with_a_byte_at_a_time_reading(text: str) -> None:
    try:
        expected: bytes | str = _unescape_byte_by_byte(text)
    except ValueError as exc:
        expected = str(exc)
    try:
        got: bytes | str = unescape(text)
    except ValueError as exc:
        got = str(exc)
    assert got == expected


def test_split_lines() -> None:
    assert split_lines(b"a\r\nb\rc\nd") == [b"a\r\n", b"b\r", b"c\n", b"d"]
    assert split_lines(b"\r\n\r\n") == [b"\r\n", b"\r\n"]


def test_load_script_from_path_or_text(tmp_path: Path) -> None:
    path = tmp_path / "s.cml"
    path.write_text("?96.1\n")
    assert load_script(path).steps[0].data == b"?96.1\r"
    assert load_script(str(path)).steps[0].data == b"?96.1\r"
    assert load_script("?96.1").steps[0].data == b"?96.1\r"
    with pytest.raises(ScriptError, match="cannot read script"):
        load_script(tmp_path / "missing.cml")


# -- running --------------------------------------------------------------
def test_golden_transcript_passes_with_the_transcript_timed() -> None:
    result = run_script(ROUNDTRIP, FakeChain())
    assert result.ok, result.summary()
    assert result.matched == result.expectations == 7
    lines = result.format().splitlines()
    assert lines[0] == "   0.000000 > ?96.1"
    assert lines[1] == "   0.000000 < ?96.1"
    assert "   1.100000 < Ux.1=8" in lines
    assert lines[-1] == "   1.100000 < Px.1=2"
    assert result.end_time == seconds(1.1)


def test_entries_carry_exact_bytes_and_script_lines() -> None:
    result = run_script("?96.1\n", FakeChain())
    assert result.transcript == [TranscriptEntry(0, ">", b"?96.1\r", 1),
                                 TranscriptEntry(0, "<", b"?96.1\r\n"),
                                 TranscriptEntry(0, "<", b"Px.1=1\r\n")]
    assert result.received == b"?96.1\r\nPx.1=1\r\n"


def test_mismatch_reports_the_first_difference_with_context() -> None:
    result = run_script("?96.1\n<< ?96.1\\r\\n\n<< Px.1=7\\r\\n\n?96.1\n", FakeChain())
    assert not result.ok and result.failure is not None
    assert result.failure.kind == "mismatch" and result.failure.line_no == 3
    message = result.failure.message
    assert 'expected "Px.1=7\\r\\n"' in message and 'sent "Px.1=1\\r\\n"' in message
    assert "differs at offset 5" in message and 'before it: "?96.1\\r\\n"' in message
    assert len(result.transcript) == 3   # the run stopped at the mismatch


def test_expectation_before_the_bytes_arrived_fails() -> None:
    result = run_script("^.1\n<< ^.1\\r\\n\n<< Ux.1=8\\r\\n\n", FakeChain())
    assert result.failure is not None and "nothing (yet)" in result.failure.message


def test_unexpected_output_after_the_last_expectation_fails() -> None:
    result = run_script("?96.1\n<< ?96.1\\r\\n\n", FakeChain())
    assert result.failure is not None and result.failure.kind == "unexpected"
    assert 'more byte(s): "Px.1=1\\r\\n"' in result.failure.message


def test_without_expectations_nothing_is_checked() -> None:
    assert run_script("?96.1\n^.1\n", FakeChain()).ok


def test_until_timeout_fails_at_the_deadline() -> None:
    chain = FakeChain()
    result = run_script("?96.1\n@until Ux.1=8 2\n?96.1\n", chain)
    assert result.failure is not None and result.failure.kind == "timeout"
    assert result.failure.line_no == 2 and "timed out after 2 s" in result.failure.message
    assert chain.kernel.now == seconds(2) and chain.counter == 1


def test_until_default_timeout_is_ten_virtual_seconds() -> None:
    chain = FakeChain()
    assert not run_script("@until never", chain).ok
    assert chain.kernel.now == seconds(DEFAULT_UNTIL_TIMEOUT)


def test_until_matches_lines_already_received_once() -> None:
    # the Px line arrived before @until ran: it matches at once; the second @until
    # does not match it again
    chain = FakeChain()
    result = run_script("?96.1\n@until ^Px\n@until ^Px 1\n", chain)
    assert result.failure is not None and result.failure.line_no == 3
    assert chain.kernel.now == seconds(1)


def test_wait_and_send_directives() -> None:
    chain = FakeChain()
    result = run_script("@wait 0.25\n@send ?96\n@send .1\\r\n<< ?96.1\\r\\nPx.1=1\\r\\n\n", chain)
    assert result.ok, result.summary()
    assert [e.time for e in result.transcript] == [seconds(0.25)] * 4
    assert [e.data for e in result.transcript if e.direction == ">"] == [b"?96", b".1\r"]


def test_blank_lines_are_sent() -> None:
    chain = FakeChain()
    run_script("?96.1\n\n?96.1\n", chain)
    assert chain.lines == ["?96.1", "", "?96.1"]


def test_until_option_runs_on_after_the_script() -> None:
    chain = FakeChain()
    result = run_script("^.1\n", chain, until=5)
    assert chain.kernel.now == seconds(5)
    assert result.transcript[-1] == TranscriptEntry(seconds(1.1), "<", b"Ux.1=8\r\n")


def test_runs_are_deterministic() -> None:
    first = run_script(ROUNDTRIP, FakeChain(pacing=True), until=3)
    second = run_script(ROUNDTRIP, FakeChain(pacing=True), until=3)
    assert first.transcript == second.transcript


def test_pacing_shows_wire_time_in_the_transcript() -> None:
    result = run_script("?96.1\n@wait 0.01\n", FakeChain(pacing=True))
    bt = byte_time_ns(38400)
    assert [(e.time, e.direction) for e in result.transcript] == [(0, ">"), (13 * bt, "<"),
                                                                 (21 * bt, "<")]


def test_echo_off_and_cr_delimiter_are_the_motor_s_business() -> None:
    result = run_script("K23.1=8\nK70.1=0\n?96.1\n", FakeChain())
    assert result.received == b"K23.1=8\r\nPx.1=1\r"
    assert result.transcript[-1].format() == "   0.000000 < Px.1=1"


def test_a_model_exception_is_a_failure_not_a_crash() -> None:
    result = run_script("boom\n?96.1\n", FakeChain())
    assert result.failure is not None and result.failure.kind == "error"
    assert "RuntimeError: fake model failure" in result.failure.message
    assert isinstance(result.exception, RuntimeError)


def test_on_entry_streams_the_transcript() -> None:
    seen: list[str] = []
    result = run_script(ROUNDTRIP, FakeChain(), on_entry=lambda e: seen.append(e.format()))
    assert seen == result.format().splitlines()


def test_record_gives_a_golden_transcript_that_passes() -> None:
    source = "# move\nS.1=100\n^.1\n@until Ux.1=8\n?96.1\n"
    recorded = run_script(source, FakeChain(), until=2).to_script()
    assert recorded == ("# move\nS.1=100\n<< S.1=100\\r\\n\n^.1\n<< ^.1\\r\\n\n@until Ux.1=8\n"
                        "<< Ux.1=8\\r\\n\n?96.1\n<< ?96.1\\r\\n\n<< Px.1=1\\r\\n\n@wait 0.9\n")
    again = run_script(recorded, FakeChain())
    assert again.ok, again.summary()


def test_trace_needs_a_recorder_and_is_closed_after_the_run(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(ScriptError, match="no trace recorder"):
        run_script("?96.1\n", FakeChain(), trace=tmp_path / "t.csv")

    class Handle:
        closed = False

        def close(self) -> None:
            Handle.closed = True

    traced: list[Path] = []

    def fake_trace(chain: Any, path: Path, step: float = 0.001, **options: Any) -> Handle:
        traced.append(path)
        return Handle()

    monkeypatch.setattr("coolmuscle.tools.trace.recorder.trace", fake_trace)
    chain = FakeChain()
    run_script("?96.1\n", chain, trace=tmp_path / "t.csv")
    assert traced == [tmp_path / "t.csv"] and Handle.closed



def test_a_failing_display_is_not_blamed_on_the_motor() -> None:
    def broken(entry: TranscriptEntry) -> None:
        raise BrokenPipeError("reader went away")
    chain = FakeChain()
    with pytest.raises(BrokenPipeError):
        run_script("?96.1\n?96.1\n", chain, on_entry=broken)
    assert chain.counter == 2


@pytest.mark.parametrize("line", ["@wait 1e308", "@until x 1e300", "@wait 1000000001"])
def test_a_wait_beyond_the_kernels_clock_is_a_script_error(line: str) -> None:
    """Waits up to 1e9 s (30 years); beyond, a bad script (exit 2), not the model's
    OverflowError in the middle of the run (an attack found that)."""
    with pytest.raises(ScriptError, match=r"seconds must be 0..1e\+09"):
        parse_script(line + "\n")


@pytest.mark.parametrize("firmware, motors, text, message", [
    ("cm2", 1, "?96.1\n@input 9 on\n", "line 2: @input 9: the motor has inputs 1..6 (cm2)"),
    ("rt3", 1, "@input 5 on\n", "line 1: @input 5: the motor has inputs 1..4 (rt3)"),
    ("cm2", 1, "@input 0 on\n", "line 1: @input 0: inputs are numbered from 1"),
    ("cm2", 2, "@input 3.1 on\n", "line 1: @input: no motor ID3 on this chain (IDs 1..2; "
     "--motors sets how many)"),
    ("cm2", 1, "@input 16.1 on\n", "line 1: @input: motor ID 16 is not 1..15"),
    ("cm2", 1, "@analog 1 1024\n", "line 1: @analog 1024: the analog input is 0..1023"),
])
def test_an_input_or_analog_line_out_of_range_is_a_script_error(
        firmware: str, motors: int, text: str, message: str,
        make_chain: ChainFactory) -> None:
    """A bad ``@input``/``@analog`` line is a bad script (exit 2) naming the line and
    the allowed range, before anything runs; not the model's IndexError mid-run."""
    chain = make_chain(motors=motors, firmware=firmware)
    with pytest.raises(ScriptError) as caught:
        run_script(text, chain)
    assert str(caught.value).startswith(message)
    assert chain.kernel.now == 0


def test_run_script_refuses_a_path_that_names_no_file(make_chain: ChainFactory) -> None:
    with pytest.raises(ScriptError, match="no such script file"):
        run_script("tests/transcripts/example.cml", make_chain())
    assert run_script(str(ROOT / "examples" / "2.1-operation.cml"), make_chain()).ok


def test_run_says_which_input_line_is_wrong_and_exits_2(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from cli_support import cli
    script = tmp_path / "inputs.cml"
    script.write_text("?96.1\n@input 9 on\n")
    code, out, err = cli(capsys, "run", str(script))
    assert (code, out) == (2, "")
    assert err == "coolmuscle: error: line 2: @input 9: the motor has inputs 1..6 (cm2)\n"

"""Reading captures (the format of docs/twin.md "The capture file"): what the
relay writes is read back with its instants and polled values; anything else is one
clean error; any text gives a result or that error (hypothesis)."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from coolmuscle.chain.machine import parse_machine
from coolmuscle.tools.script import run_script
from coolmuscle.tools.twin.session import CaptureError, parse_session, read_session
from fixtures import ChainFactory
from twin_support import HIDDEN_TOML, capture_text, session_plan

ROOT = Path(__file__).resolve().parents[1]

#: The example of the agreed format (capture-format.md), completed where it says "...".
FORMAT_EXAMPLE = ("# coolmuscle capture: port=socket://127.0.0.1:5150 baud=38400 parity=none "
                  "echo=on started=2026-12-03T10:00:00.123456Z\n") + """\
# chain: motors=1 firmware=cm2
# t=0.000000 >
S.1=100
# t=0.001310 <
<< S.1=100\\r\\n
@wait 0.250113
# t=0.251423 >
?96.1
# t=0.252601 <
<< ?96.1\\r\\n
# t=0.253422 <
@until ^Px\\.1=0$ 2.0
<< Px.1=0\\r\\n
# end: sent=2 received=3 bytes_to_motor=14 bytes_from_motor=25 stopped=ctrl-c
"""


@pytest.fixture(scope="module")
def exact_text() -> str:
    return capture_text(session_plan(), noise=False)


def test_the_agreed_format_example_reads_with_its_instants() -> None:
    session = parse_session(FORMAT_EXAMPLE, "example.cml")
    assert [(line.time, line.text) for line in session.sent] == [(0.0, "S.1=100"),
                                                                 (0.251423, "?96.1")]
    assert [(line.time, line.text) for line in session.received] == [
        (0.00131, "S.1=100"), (0.252601, "?96.1"), (0.253422, "Px.1=0")]
    (poll,) = session.polls
    assert (poll.motor, poll.quantity, poll.value, poll.asked, poll.time) == \
        (1, "Px", 0, 0.251423, 0.253422)
    assert session.baud == 38400 and session.bits_per_byte == 10
    assert session.end is not None and session.end["stopped"] == "ctrl-c"
    assert (session.motors, session.firmware) == (1, "cm2")


def test_a_capture_of_the_hidden_machine_replays_with_check_and_no_difference(
        exact_text: str, make_chain: ChainFactory) -> None:
    """The capture is a golden transcript: `run --check` on the hidden machine matches
    every line (a capture replays with --check with 0 differences)."""
    session = parse_session(exact_text)
    chain = make_chain(machine=parse_machine(HIDDEN_TOML))
    try:
        result = run_script(session.script, chain)
    finally:
        chain.close()
    assert result.ok, result.summary()
    assert result.matched == len(session.received) > 3000
    quantities = {p.quantity for p in session.polls}
    assert quantities == {"Px", "Pe", "Ix"}
    assert all(p.asked <= p.time for p in session.polls)
    assert [line.time for line in session.sent] == sorted(line.time for line in session.sent)


def test_a_transcript_that_is_not_a_capture_is_refused_in_one_line() -> None:
    with pytest.raises(CaptureError, match="not a capture: its first line"):
        read_session(ROOT / "examples" / "2.1-operation.cml")


@pytest.mark.parametrize("text, message", [
    ("# t=0.1 >\n?96.1\n", "not a capture"),
    (FORMAT_EXAMPLE.replace("# t=0.251423 >", "# t=zero >"), "bad time stamp"),
    (FORMAT_EXAMPLE.replace("# t=0.000000 >", "# t=0.3 >"), "goes back in time"),
    (FORMAT_EXAMPLE.replace("# t=0.251423 >\n", ""), "without its '# t=SECONDS >'"),
    (FORMAT_EXAMPLE.replace("# t=0.001310 <\n", ""), "without its '# t=SECONDS <'"),
    (FORMAT_EXAMPLE + "# t=9.0 >\n", "not followed by its line"),
    (FORMAT_EXAMPLE + "@input 1 on\n", "no place in a capture"),
    (FORMAT_EXAMPLE.replace("baud=38400", "baud=fast"), "baud=fast"),
    (FORMAT_EXAMPLE.replace("motors=1", "motors=16"), "motors=16"),
    (FORMAT_EXAMPLE.replace("<< S.1=100\\r\\n", "<< S.1=100\\q"), "bad escape"),
])
def test_a_broken_capture_is_one_error_naming_the_line(text: str, message: str) -> None:
    with pytest.raises(CaptureError, match=message) as info:
        parse_session(text, "broken.cml")
    assert "\n" not in str(info.value)


def test_files_that_are_not_text_are_refused(tmp_path: Path) -> None:
    binary = tmp_path / "b.cml"
    binary.write_bytes(b"# coolmuscle capture: baud=38400\n\xff\xfe\x00")
    for path, message in ((binary, "not UTF-8"), (tmp_path / "none.cml", "cannot read"),
                          (tmp_path, "a directory"), (Path("/dev/zero"), "a device")):
        with pytest.raises(CaptureError, match=message):
            read_session(path)


_LINES = st.sampled_from([
    "# t=0.5 >", "# t=0.6 <", "# t=1e3 >", "?96.1", "<< Px.1=3\\r\\n", "<< \\x", "@wait 0.1",
    "@until ^Px$ 1", "@until (", "# chain: motors=2 firmware=rt3", "# chain: motors=x",
    "# end: sent=1", "# end: oops", "@input 1 on", "", "#", "<<", "<< Ux.1=8\\r\\n",
    "@send \\e", "# t=0.7 <", "P.1=1000"])


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(_LINES, max_size=12), st.text(max_size=40), st.booleans())
def test_any_text_gives_a_session_or_one_capture_error(lines: list[str], noise: str,
                                                       header: bool) -> None:
    text = ("# coolmuscle capture: baud=9600 echo=on\n" if header else "") \
        + "\n".join(lines) + "\n" + noise
    try:
        session = parse_session(text, "fuzz.cml")
    except CaptureError as exc:
        assert str(exc) and "\n" not in str(exc)
        return
    assert all(p.asked <= p.time for p in session.polls)
    assert len(session.polls) <= len(session.received)

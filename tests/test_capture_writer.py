"""The session writer shared by ``coolmuscle capture`` and ``term``'s ``:log``
(docs/user-guide.md "coolmuscle capture", docs/scripts.md).

Whatever bytes go either way, in whatever pieces and at whatever instants, the file
parses as a script, its ``<<`` lines say exactly the bytes received, its sent lines
and ``@send`` lines exactly the bytes sent, each ``@until`` matches the line it stands
before (as the runner splits lines), the ``# t=`` stamps never go back, and the
``@wait`` lines bring the replay to each line sent at the instant it was sent.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

from hypothesis import example, given, settings
from hypothesis import strategies as st

from coolmuscle.tools.script import parse_script
from coolmuscle.tools.script.runner import split_lines
from coolmuscle.tools.script.transcript import LineFile, SessionWriter, until_pattern

ROOT = Path(__file__).resolve().parents[1]

# bytes a host line carries, line ends and lookalikes of script syntax made likely
_PIECES = st.one_of(
    st.binary(max_size=12),
    st.sampled_from([b"\r", b"\n", b"\r\n", b"S.1=100\r", b"?96.1\r", b"Px.1=0\r\n",
                     b"# x\r", b"@wait 1\r", b"<< a\r", b"<<x\r", b"#2.1\r", b"@1.1\r",
                     b"\\", b"\x00\x85\xff", b" \t", b"$\r"]))
_EVENTS = st.lists(st.tuples(st.sampled_from([">", "<"]), st.lists(_PIECES, max_size=4),
                             st.floats(0, 2.5, allow_nan=False),
                             st.booleans()), max_size=40)


def _record(events: list[tuple[str, list[bytes], float, bool]]) -> tuple[str, bytes, bytes]:
    lines: list[str] = []
    writer = SessionWriter(lines.append, stamps=True)
    at = 0.0
    sent, received = bytearray(), bytearray()
    for direction, pieces, gap, idle in events:
        at += gap
        data = b"".join(pieces)
        writer.feed(at, ">" if direction == ">" else "<", data)
        (sent if direction == ">" else received).extend(data)
        if idle:
            writer.tick()
    writer.finish()
    return "".join(lines), bytes(sent), bytes(received)


@settings(max_examples=300, deadline=None)
@given(_EVENTS)
# the LF of a CRLF split by a pause, while a line was being sent: the part sent goes first
@example([("<", [b"\r"], 0.0, False), (">", [b"\x00"], 0.0, False), ("<", [b"\n"], 1.0, False)])
def test_any_bytes_both_ways_make_a_script_that_says_them_exactly(events: list[
        tuple[str, list[bytes], float, bool]]) -> None:
    _says_them_exactly(events)


def _says_them_exactly(events: list[tuple[str, list[bytes], float, bool]]) -> None:
    text, sent, received = _record(events)
    assert text.isascii()
    script = parse_script(text)                           # never a ScriptError
    steps = script.lines
    assert b"".join(s.data for s in steps if s.kind == "expect") == received
    assert b"".join(s.data for s in steps if s.kind in ("send", "raw")) == sent
    # every @until matches the received line it stands before (as the runner splits)
    for i, step in enumerate(steps):
        if step.kind == "until":
            after = next(s for s in steps[i:] if s.kind == "expect")
            assert step.pattern is not None
            assert step.pattern.search(after.data.rstrip(b"\r\n").decode("latin-1"))
            assert len(split_lines(after.data)) == 1
    # stamps never go back (but for bytes received without a line end, written when the
    # capture ends); the replay stands at each sent line's instant (6 decimals)
    replay, last_stamp = 0.0, 0.0
    stamp: float | None = None
    for i, step in enumerate(steps):
        if step.kind == "comment" and (m := re.match(r"# t=([0-9.]+) ([<>])$", step.source)):
            stamp = float(m.group(1))
            after = next((s for s in steps[i:] if s.kind in ("expect", "send", "raw")), None)
            partial = (m.group(2) == "<" and after is not None
                       and not after.data.endswith((b"\r", b"\n")))
            assert stamp >= last_stamp or partial
            last_stamp = max(stamp, last_stamp)
        elif step.kind == "wait":
            replay += step.seconds
        elif step.kind == "until":
            assert stamp is not None
            replay = max(replay, stamp)        # the motor says it when it said it here
        elif step.kind in ("send", "raw"):
            assert stamp is not None
            assert abs(replay - stamp) <= 1e-6 + 1e-9, (replay, stamp, step.source)  # 2 roundings


@settings(max_examples=300, deadline=None)
@given(_EVENTS)
def test_long_lines_go_out_in_pieces_that_still_say_the_bytes_exactly(events: list[
        tuple[str, list[bytes], float, bool]]) -> None:
    """The same, with pieces of at most 5 bytes instead of 64 KiB: a line longer than
    that goes out in pieces as it comes, and the file still says exactly every byte
    each way, stamps and waits as above."""
    from unittest import mock

    import coolmuscle.tools.script.transcript as transcript
    with mock.patch.object(transcript, "MAX_PIECE", 5):
        _says_them_exactly(events)


def test_a_64_kib_piece_at_most_whatever_the_line_length() -> None:
    """A 1 MiB line each way without a line end: 16 pieces each, none longer than
    64 KiB of bytes, and the ends of the lines after them as usual."""
    lines: list[str] = []
    writer = SessionWriter(lines.append)
    for n in range(16):
        writer.feed(n * 0.01, ">", b"\x01" * (1 << 16))
        writer.feed(n * 0.01, "<", b"A" * (1 << 16))
    writer.feed(1.0, ">", b"\r")
    writer.feed(1.0, "<", b"\r\n")
    writer.finish()
    text = "".join(lines)
    sends = [line for line in text.splitlines() if line.startswith("@send ")]
    expects = [line for line in text.splitlines() if line.startswith("<< ")]
    assert len(sends) == 17 and sends[-1] == "@send \\r"
    assert len(expects) == 17 and expects[-1] == "<< \\r\\n"
    assert max(len(line) for line in sends + expects) <= 4 * (1 << 16) + 8
    assert "@until" not in text
    steps = parse_script(text).lines
    assert b"".join(s.data for s in steps if s.kind == "expect") == b"A" * (1 << 20) + b"\r\n"


def test_a_session_reads_as_the_format_says() -> None:
    """The example of the agreed format: command lines, echoes, a reply with @until."""
    lines: list[str] = []
    writer = SessionWriter(lines.append, stamps=True)
    writer.feed(0.0, ">", b"S.1=100\r")
    writer.feed(0.00131, "<", b"S.1=100\r\n")
    writer.feed(0.251423, ">", b"?96.1\r")
    writer.feed(0.252601, "<", b"?96.1\r\nPx.1")
    writer.feed(0.253422, "<", b"=0\r\n")
    writer.feed(0.3, "<", b"Ux.1")                  # a partial line at the end
    writer.finish()
    assert "".join(lines) == (
        "# t=0.000000 >\nS.1=100\n"
        "# t=0.001310 <\n<< S.1=100\\r\\n\n"
        "@wait 0.251423\n# t=0.251423 >\n?96.1\n"
        "# t=0.252601 <\n<< ?96.1\\r\\n\n"
        "# t=0.253422 <\n@until ^Px\\.1=0$ 2.0\n<< Px.1=0\\r\\n\n"
        "@wait 0.046578\n# t=0.300000 <\n<< Ux.1\n")
    assert (writer.sent_lines, writer.received_lines) == (2, 4)
    assert (writer.bytes_sent, writer.bytes_received) == (14, 28)


def test_lines_that_are_not_plain_cml_go_out_as_send() -> None:
    lines: list[str] = []
    writer = SessionWriter(lines.append)
    for data in (b"# not a comment\r", b"@wait 5\r", b"<< x\r", b"S.1=1\n", b"K23.1=1\r\n",
                 b"\tT\r", b"#2.1\r", b"@1.1\r", b"\r"):
        writer.feed(0.0, ">", data)
    assert lines == ["@send # not a comment\\r\n", "@send @wait 5\\r\n", "@send << x\\r\n",
                     "@send S.1=1\\n\n", "K23.1=1\n", "@send \\n\n", "@send \\tT\\r\n",
                     "#2.1\n", "@1.1\n", "\n"]


def test_a_line_cut_by_a_report_goes_out_in_two_parts_in_stream_order() -> None:
    """A person types ``?96.1`` while ``Ux.1=8`` comes: the part typed before the report
    goes first, so the replay sends the bytes in the order the motor got them."""
    lines: list[str] = []
    writer = SessionWriter(lines.append)
    writer.feed(0.0, ">", b"?9")
    writer.feed(0.01, "<", b"?9")                   # the echo, byte by byte
    writer.feed(0.5, "<", b"Ux.1=8\r\n")
    writer.feed(0.6, ">", b"6.1\r")
    writer.feed(0.61, "<", b"6.1\r\nPx.1=0\r\n")
    writer.finish()
    assert lines == ["@send ?9\n", "@until ^\\?9Ux\\.1=8$ 3.0\n<< ?9Ux.1=8\\r\\n\n",
                     "@wait 0.100000\n", "@send 6.1\\r\n", "@until ^6\\.1$ 2.0\n<< 6.1\\r\\n\n",
                     "@until ^Px\\.1=0$ 2.0\n<< Px.1=0\\r\\n\n"]


def test_a_lone_cr_waits_for_its_lf_then_stands_alone() -> None:
    lines: list[str] = []
    writer = SessionWriter(lines.append)
    writer.feed(0.0, "<", b"Ux.1=8\r")
    assert lines == []                              # its LF may come
    writer.tick()                                   # nothing came: the line is complete
    writer.feed(0.2, "<", b"\nIN.1=04\r\n")
    assert "".join(lines) == ("@until ^Ux\\.1=8$ 2.0\n<< Ux.1=8\\r\n<< \\n\n"
                              "@until ^IN\\.1=04$ 2.4\n<< IN.1=04\\r\\n\n")


def test_until_patterns_match_only_their_line() -> None:
    for text in (b"Px.1=0", b"a b", b"(x)*+?", b"\x00\xff\x85", b"ID1 : CM2v3.10R.1 #0802"):
        pattern = re.compile(until_pattern(text))
        assert pattern.search(text.decode("latin-1"))
        assert not pattern.search(text.decode("latin-1") + "x")
        assert until_pattern(text).isascii()


def test_term_log_keeps_hundredths_and_its_header(tmp_path: Path) -> None:
    from coolmuscle.tools.script.transcript import TranscriptRecorder
    log = tmp_path / "log.cml"
    recorder = TranscriptRecorder(log, "socket://x")
    recorder.tap(">", b"?96.1\r")
    recorder.tap("<", b"?96.1\r\nPx.1=0\r\n")
    recorder.close()
    assert log.read_text() == ("# golden transcript recorded by coolmuscle term (socket://x)\n"
                               "?96.1\n<< ?96.1\\r\\n\n@until ^Px\\.1=0$ 2.0\n<< Px.1=0\\r\\n\n")


_FULL_DISK = r"""
import os, resource, signal, sys
from coolmuscle.tools.script.transcript import LineFile
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)     # EFBIG instead of death
resource.setrlimit(resource.RLIMIT_FSIZE, (1000, 1000))
said = []
f = LineFile(sys.argv[1], said.append)
for i in range(200):
    f.write(f"<< line number {i} of a long session\\r\\n\n")
f.close()
print(len(said), said[0])
"""


def test_a_file_that_stops_growing_says_so_once_and_keeps_whole_lines(tmp_path: Path) -> None:
    """A file size limit (RLIMIT_FSIZE: EFBIG, as a full disk gives ENOSPC): one
    sentence, the file cut back to its last whole line, no more writes tried."""
    out = tmp_path / "s.cml"
    done = subprocess.run([sys.executable, "-c", _FULL_DISK, str(out)], capture_output=True,
                          text=True, timeout=60, env={**os.environ,
                                                      "PYTHONPATH": str(ROOT / "src")})
    assert done.returncode == 0, done.stderr
    count, sentence = done.stdout.split(" ", 1)
    assert count == "1" and "stopped growing at" in sentence and "File too large" in sentence
    data = out.read_bytes()
    assert 900 < len(data) <= 1000 and data.endswith(b"\n")
    parse_script(data.decode())


def test_line_file_writes_each_call_at_once(tmp_path: Path) -> None:
    path = tmp_path / "f.cml"
    f = LineFile(path)
    f.write("a\n")
    assert path.read_text() == "a\n"                # no buffer between us and the kernel
    f.write("b\n")
    f.close()
    assert path.read_text() == "a\nb\n" and f.size == 4


def test_the_rounding_of_many_waits_does_not_add_up() -> None:
    """10,000 lines a third of a microsecond off the grid each: the replay is still
    within a microsecond of the last one's instant (each wait makes up the last)."""
    lines: list[str] = []
    writer = SessionWriter(lines.append)
    at = 0.0
    for _ in range(10_000):
        at += 0.0100003333
        writer.feed(at, ">", b"?96.1\r")
    waits = sum(float(line.split()[1]) for line in lines if line.startswith("@wait"))
    assert abs(waits - at) < 1e-6

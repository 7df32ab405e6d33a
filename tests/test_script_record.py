"""A run's transcript as it happens (tools/script/record.py, compiled; docs/scripts.md).

The recorder's fast path for one whole CR LF line, the display's shortcut for a plain
one and the time written from the integer must give what the general code gives, byte
for byte; a transcript entry stays a frozen dataclass, compiled or not."""

from __future__ import annotations

import dataclasses
import json
import os
import pickle
import subprocess
import sys
from types import SimpleNamespace

import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from coolmuscle.sim.kernel import to_seconds
from coolmuscle.tools.script.record import (
    LineWriter,
    Recorder,
    TranscriptEntry,
    seconds_text,
    strip_end,
)


# -- the time ---------------------------------------------------------------
@given(st.integers(0, 2 * 10**15) | st.integers(0, 10**7)
       | st.integers(0, 10**12).map(lambda us: us * 1000 + 500))
def test_seconds_text_is_the_float_formatted(ns: int) -> None:
    """From the integer below 1e15 ns, off a half microsecond; as the float elsewhere:
    always what ``f"{to_seconds(ns):11.6f}"`` writes."""
    assert seconds_text(ns) == f"{to_seconds(ns):11.6f}"


@pytest.mark.parametrize("ns", [0, 499, 500, 501, 999_999_500, 999_999_499, 9_999_999_999_499,
                                10_000_000_000_000, 10**15 - 1, 10**15, 999_999_999_999_999,
                                2**53 + 1, 10**18])
def test_seconds_text_at_the_edges(ns: int) -> None:
    """Half microseconds, a fifth digit of whole seconds, the limit of the integer path."""
    assert seconds_text(ns) == f"{to_seconds(ns):11.6f}"


def test_seconds_text_every_nanosecond_of_a_few_milliseconds() -> None:
    for start in (0, 10**9 - 2_000_000, 7_345_678_901_000):
        for ns in range(start, start + 2_000_000, 7):
            assert seconds_text(ns) == f"{to_seconds(ns):11.6f}", ns


@given(st.binary(max_size=6))
def test_strip_end_takes_off_one_line_end(data: bytes) -> None:
    if data.endswith(b"\r\n"):
        assert strip_end(data) == data[:-2]
    elif data.endswith((b"\r", b"\n")):
        assert strip_end(data) == data[:-1]
    else:
        assert strip_end(data) == data


# -- the recorder -------------------------------------------------------------
class Display:
    """A LineWriter's ``write`` that can be told to fail at its n-th line."""

    def __init__(self, fail_at: int | None = None) -> None:
        self.text: list[str] = []
        self.fail_at = fail_at

    def write(self, text: str) -> int:
        if self.fail_at is not None and len(self.text) == self.fail_at:
            raise BrokenPipeError("reader went away")
        self.text.append(text)
        return len(text)


def record(chunks: list[tuple[int, bytes]], split: bool,
           fail_at: int | None = None) -> tuple[Recorder, Display]:
    """Feed ``(time, bytes)`` to a recorder whole, or (``split``) a byte at a time."""
    kernel = SimpleNamespace(now=0)
    display = Display(fail_at)
    recorder = Recorder(kernel, LineWriter(display.write))
    for time, data in chunks:
        kernel.now = time
        for piece in ([data[i:i + 1] for i in range(len(data))] if split else [data]):
            recorder.on_bytes(piece)
    recorder.finish()
    return recorder, display


#: Reports and replies (the fast path), lines with bytes to escape, CR-only and LF-only
#: ends, a CR whose LF comes in the next chunk, pieces of lines.
_CHUNK = st.sampled_from([b"Ux.1=8\r\n", b"Px.15=-2000\r\n", b"\r\n", b"a\\b\r\n",
                          b"\x00\xff\r\n", b"ok\r", b"\n", b"x\ny\r\n", b"\r\r\n", b"half",
                          b"Ux.2=8"]) | st.binary()


@given(st.lists(st.tuples(st.integers(0, 10**12), _CHUNK), max_size=12))
@example([(0, b"Ux.1=8\r\n"), (1, b"ok\r"), (2, b"\n"), (3, b"Ux.1=8\r\n")])
@example([(5, b"part"), (6, b"Ux.1=8\r\n")])
def test_whole_chunks_record_what_bytes_one_at_a_time_record(
        chunks: list[tuple[int, bytes]]) -> None:
    """The fast path (one CR LF line) and the display's shortcut for a plain one give
    the entries, lines and text of the byte loop; the text is each entry's format()."""
    whole, shown = record(sorted(chunks), split=False)
    loop, shown_loop = record(sorted(chunks), split=True)
    assert whole.entries == loop.entries and whole.lines == loop.lines
    assert bytes(whole.stream) == bytes(loop.stream) == b"".join(d for _, d in sorted(chunks))
    assert shown.text == shown_loop.text == [e.format() + "\n" for e in whole.entries]


@pytest.mark.parametrize("chunks", [[b"Ux.1=8\r\n"] * 3, [b"a\\b\r\n"] * 3,
                                    [b"ok\r", b"x\r\n"] * 2])
def test_a_failing_display_stops_being_written_and_the_record_goes_on(
        chunks: list[bytes]) -> None:
    recorder, display = record([(t, c) for t, c in enumerate(chunks)], split=False, fail_at=1)
    assert isinstance(recorder.display_error, BrokenPipeError)
    assert len(display.text) == 1 and len(recorder.entries) >= 3


# -- the entry ------------------------------------------------------------------
_ENTRY_CHECKS = """
import dataclasses, json, pickle, sys
import coolmuscle._accel as accel
from coolmuscle.tools.script.runner import TranscriptEntry
e = TranscriptEntry(1_100_000_000, "<", b"Ux.1=8\\r\\n")
try:
    e.time = 5  # type: ignore[misc]
    frozen = "assigned"
except dataclasses.FrozenInstanceError as exc:
    frozen = str(exc)
print(json.dumps({"compiled": accel.active(), "repr": repr(e), "format": e.format(),
    "frozen": frozen, "pickle": pickle.loads(pickle.dumps(e)) == e,
    "hash": hash(e) == hash(TranscriptEntry(1_100_000_000, "<", b"Ux.1=8\\r\\n")),
    "replace": repr(dataclasses.replace(e, direction=">", line_no=3)),
    "asdict": repr(dataclasses.asdict(e)),
    "fields": [f.name for f in dataclasses.fields(e)],
    "keywords": repr(TranscriptEntry(time=0, direction=">", data=b"x", line_no=2))}))
"""


def _entry_checks(pure: bool) -> dict[str, object]:
    env = {**os.environ, "COOLMUSCLE_PURE": "1" if pure else ""}
    out = subprocess.run([sys.executable, "-c", _ENTRY_CHECKS], env=env, capture_output=True,
                         text=True, timeout=60, check=True).stdout
    result: dict[str, object] = json.loads(out)
    return result


def test_a_transcript_entry_is_the_same_frozen_dataclass_compiled_and_as_sources() -> None:
    compiled, pure = _entry_checks(False), _entry_checks(True)
    assert pure.pop("compiled") is False
    compiled.pop("compiled")
    assert compiled == pure == {
        "repr": "TranscriptEntry(time=1100000000, direction='<', data=b'Ux.1=8\\r\\n', "
                "line_no=None)",
        "format": "   1.100000 < Ux.1=8", "frozen": "cannot assign to field 'time'",
        "pickle": True, "hash": True,
        "replace": "TranscriptEntry(time=1100000000, direction='>', data=b'Ux.1=8\\r\\n', "
                   "line_no=3)",
        "asdict": "{'time': 1100000000, 'direction': '<', 'data': b'Ux.1=8\\r\\n', "
                  "'line_no': None}",
        "fields": ["time", "direction", "data", "line_no"],
        "keywords": "TranscriptEntry(time=0, direction='>', data=b'x', line_no=2)"}


def test_entries_pickle_in_this_process() -> None:
    entries = [TranscriptEntry(0, ">", b"?96.1\r", 1), TranscriptEntry(7, "<", b"x\r\n")]
    assert pickle.loads(pickle.dumps(entries)) == entries
    assert dataclasses.replace(entries[0], time=9).time == 9

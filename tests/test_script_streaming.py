"""A run of any length in bounded memory: ``coolmuscle run`` streams its transcript and
checks as the bytes come, keeping nothing of it (docs/scripts.md, tools/script/runner.py
``keep``).

Streaming must not change a verdict: every golden transcript, and failing variants of
them (an expectation changed, one dropped, an ``@until`` that never comes), give the
same result, message and printed lines with and without ``keep``.  A long run's peak
memory does not grow with the simulated time.
"""

from __future__ import annotations

import re
import sys
import tracemalloc
from pathlib import Path

import pytest

from coolmuscle.chain.daisy import Chain
from coolmuscle.tools.cli.run import run_command
from coolmuscle.tools.script.record import LineWriter
from coolmuscle.tools.script.runner import RunResult, ScriptError, parse_script, run_script
from test_transcripts import chain_options, transcript_files

#: One motor looping a PTP bank of 1.1 s moves, as bench_speed's first row.
LOOP = ("S1.1=100\nA1.1=100\nP1.1=10000\nP2.1=0\nB1.1\nX0\nS1.1, A1.1, P1.1\nP2.1\nX-\n"
        "END\n[1.1\n")


def _run(text: str, path: Path, tmp_path: Path, keep: bool,
         record: list[str] | None = None) -> tuple[RunResult, list[str]]:
    options = chain_options(text)
    if options.pop("state", None):
        options["state_dir"] = tmp_path / ("kept" if keep else "streamed")
    if "machine" in options:
        options["machine"] = path.parent / str(options["machine"])
    shown: list[str] = []
    chain = Chain(**options)  # type: ignore[arg-type]
    try:
        result = run_script(parse_script(text), chain, on_entry=LineWriter(shown.append),
                            keep=keep, record=None if record is None else record.append)
    finally:
        chain.close()
    return result, shown


def _variants(text: str) -> list[str]:
    """The transcript, and the same with its last expectation changed, its last one
    dropped (the bytes then come unexpected) and an @until that never comes."""
    rows = text.split("\n")
    expects = [i for i, row in enumerate(rows) if row.startswith("<< ")]
    last = expects[-1]
    changed = rows[:last] + [rows[last][:-1] + ("0" if rows[last][-1] != "0" else "1")] \
        + rows[last + 1:]
    dropped = rows[:last] + rows[last + 1:]
    first = expects[0]
    never = rows[:first] + ["@until no motor says this 0.5"] + rows[first:]
    return ["\n".join(v) for v in (rows, changed, dropped, never)]


@pytest.mark.parametrize("path", transcript_files(), ids=lambda p: p.stem)
def test_streaming_gives_the_verdict_and_lines_of_a_kept_run(path: Path,
                                                             tmp_path: Path) -> None:
    text = path.read_text(encoding="utf-8")
    for variant in _variants(text):
        kept, kept_shown = _run(variant, path, tmp_path, keep=True)
        golden: list[str] = []
        streamed, shown = _run(variant, path, tmp_path, keep=False, record=golden)
        assert streamed.failure == kept.failure
        assert "".join(golden) == kept.to_script()
        assert (streamed.matched, streamed.end_time, streamed.marks) == \
            (kept.matched, kept.end_time, kept.marks)
        assert shown == kept_shown
        assert streamed.transcript == [] and streamed.received == b""
        assert kept_shown == [entry.format() + "\n" for entry in kept.transcript]


def test_an_until_met_by_lines_that_came_before_it() -> None:
    """Lines received before an ``@until`` runs count, in order, each line meeting one
    ``@until`` at most; a streamed run keeps no line to look back at."""
    text = ("P.1=100\n^.1\n@wait 2\n?96.1\n@until Ux\\.1=8\n@until Ux\\.1=8 0.5\n"
            "@until Px\\.1=\n")
    results = []
    for keep in (True, False):
        chain = Chain()
        try:
            result = run_script(parse_script(text), chain, keep=keep)
        finally:
            chain.close()
        results.append(result)
        assert result.failure is not None and result.failure.kind == "timeout"
        assert result.failure.line_no == 6        # one Ux.1=8 for two @until
    assert results[0].failure == results[1].failure


class _Sink:
    """stdout for a run: counts the lines written, keeps none."""

    def __init__(self) -> None:
        self.lines = 0

    def write(self, text: str) -> int:
        self.lines += text.count("\n")
        return len(text)

    def flush(self) -> None:
        pass


def _peak(script: Path, until: float, monkeypatch: pytest.MonkeyPatch) -> tuple[int, int]:
    """The peak of memory allocated while ``coolmuscle run SCRIPT --until UNTIL`` runs
    in this process (tracemalloc), and the lines it printed."""
    sink = _Sink()
    with monkeypatch.context() as patch:
        patch.setattr(sys, "stdout", sink)
        tracemalloc.reset_peak()
        status = run_command(script, until=until)
        peak = tracemalloc.get_traced_memory()[1]
    assert status == 0
    return peak, sink.lines


def test_a_long_run_prints_every_line_in_bounded_memory(tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """``coolmuscle run`` of a motor looping its bank: 6,000 more simulated seconds
    (about 5,500 more lines printed) do not raise the peak.  Before, the run kept every
    entry, line and byte: 1.4 MiB more here, 107 MiB over 100 h."""
    script = tmp_path / "loop.cml"
    script.write_text(LOOP, encoding="utf-8")
    tracemalloc.start()
    try:
        _peak(script, 100, monkeypatch)                    # imports, first solutions
        short, short_lines = _peak(script, 2000, monkeypatch)
        long, long_lines = _peak(script, 8000, monkeypatch)
    finally:
        tracemalloc.stop()
    assert long_lines > short_lines + 5000
    assert long - short < 256 * 1024, (short, long)


def test_a_long_recorded_run_writes_every_line_in_bounded_memory(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``coolmuscle run --record``: the golden transcript is written as the run goes,
    nothing of it kept; before, ``--record`` kept the whole run to write it at the end."""
    script = tmp_path / "loop.cml"
    script.write_text(LOOP, encoding="utf-8")
    record = tmp_path / "golden.cml"
    sink = _Sink()
    peaks = []
    tracemalloc.start()
    try:
        with monkeypatch.context() as patch:
            patch.setattr(sys, "stdout", sink)
            for until in (100, 2000, 8000):
                tracemalloc.reset_peak()
                assert run_command(script, until=until, record=record) == 0
                peaks.append(tracemalloc.get_traced_memory()[1])
    finally:
        tracemalloc.stop()
    assert len(re.findall(r"^<< ", record.read_text(encoding="utf-8"), re.MULTILINE)) > 7000
    assert peaks[2] - peaks[1] < 256 * 1024, peaks


def test_record_still_writes_the_whole_golden_transcript(tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """``--record`` keeps what it writes: every line received, as before."""
    script = tmp_path / "loop.cml"
    script.write_text(LOOP, encoding="utf-8")
    record = tmp_path / "golden.cml"
    sink = _Sink()
    monkeypatch.setattr(sys, "stdout", sink)
    assert run_command(script, until=30, record=record) == 0
    golden = record.read_text(encoding="utf-8")
    assert len(re.findall(r"^<< ", golden, re.MULTILINE)) == sink.lines - LOOP.count("\n")
    assert run_command(record, check=True) == 0


def test_a_run_that_does_not_end_leaves_the_record_as_it_was(tmp_path: Path) -> None:
    """``--record`` writes beside the file and replaces it when the run has ended: a run
    stopped by an error (here a script error found as it starts) leaves the file whole
    and no temporary file behind."""
    script = tmp_path / "bad.cml"
    script.write_text("?96.1\n@input 9 on\n", encoding="utf-8")
    record = tmp_path / "golden.cml"
    record.write_text("?96.1\n<< Ux.1=8\\r\\n\n", encoding="utf-8")
    with pytest.raises(ScriptError):
        run_command(script, record=record)
    assert record.read_text(encoding="utf-8") == "?96.1\n<< Ux.1=8\\r\\n\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.cml", "golden.cml"]


@pytest.mark.parametrize("where", ["/", "."])
def test_record_into_a_directory_is_refused_before_the_run(tmp_path: Path, where: str) -> None:
    """``--record /`` or a directory: one ScriptError at once (exit 2), not a traceback
    and not after the whole run."""
    script = tmp_path / "s.cml"
    script.write_text("?96.1\n", encoding="utf-8")
    target = Path(where) if where == "/" else tmp_path
    with pytest.raises(ScriptError, match="it is a directory"):
        run_command(script, record=target)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.cml"]

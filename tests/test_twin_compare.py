"""``coolmuscle compare`` (docs/twin.md): a capture of a "real" motor (a hidden machine,
tests/twin_support.py) against the virtual motor: with the hidden machine every line
is within tolerance; with the default machine the differences are found and named;
timing, missing lines and the report and plot files are what they say."""

from __future__ import annotations

import base64
import re
import struct
from html.parser import HTMLParser
from pathlib import Path

import pytest

from coolmuscle.tools.twin.compare import Tolerance, compare_session
from twin_support import write_capture, write_hidden


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("twin")
    write_capture(out, "noisy.cml", seed=3)
    write_capture(out, "exact.cml", noise=False)
    write_hidden(out)
    return out


def test_against_the_hidden_machine_every_line_is_within_tolerance(folder: Path) -> None:
    for name in ("exact.cml", "noisy.cml"):
        report = compare_session(folder / name, folder / "hidden.toml")
        assert report.ok, [v.describe() for v in report.differences[:5]]
        counts = report.counts()
        assert counts["equal"] + counts["close"] == len(report.session.received)
    # with noise on the polled values some differ, all within the band they are given
    report = compare_session(folder / "noisy.cml", folder / "hidden.toml")
    assert report.counts()["close"] > 300


def test_against_the_default_machine_the_differences_are_found_and_named(folder: Path) -> None:
    report = compare_session(folder / "noisy.cml")
    assert not report.ok and report.machine == "the default machine"
    diffs = report.differences
    by_quantity = {v.real.text.split(".")[0] for v in diffs if v.real is not None}
    assert {"Pe", "Ix", "Px"} <= by_quantity
    # cruising at 10 000 pps: the hidden loop (kp 220) lags 45 pulses, the default (300) 33
    cruise = next(v for v in diffs if v.real is not None and v.real.text.startswith("Pe")
                  and 1.0 < v.real.time < 1.5)
    assert cruise.kind == "value" and cruise.band is not None
    real = int(cruise.real.text.split("=")[1])
    virtual = int(cruise.virtual.text.split("=")[1]) if cruise.virtual else 0
    assert 43 <= real <= 47 and virtual == 33
    assert cruise.band[1] < real and cruise.off == pytest.approx(real - cruise.band[1], abs=1e-3)
    line = cruise.describe()
    assert f"line {cruise.real.line_no}" in line and "different value" in line
    # without the stopper the virtual motor reaches the push target: it says Ux.1=8 more
    extra = [v for v in diffs if v.kind == "extra"]
    assert [v.virtual.text for v in extra if v.virtual] == ["Ux.1=8"]


def _delay(text: str, line: str, by: float) -> str:
    """Move the first ``<< line`` (with its stamp and @until) ``by`` seconds later."""
    rows = text.split("\n")
    i = rows.index(f"<< {line}")
    block = rows[i - 2:i + 1]                       # stamp, @until, <<
    assert block[0].startswith("# t=") and block[1].startswith("@until")
    t = float(block[0][4:-2]) + by
    del rows[i - 2:i + 1]
    j = next(k for k in range(i - 2, len(rows))
             if rows[k].startswith("# t=") and float(rows[k][4:-2]) > t)
    rows[j:j] = [f"# t={t:.6f} <"] + block[1:]
    return "\n".join(rows)


def test_a_late_report_is_a_timing_difference_with_its_tolerance(folder: Path,
                                                                 tmp_path: Path) -> None:
    text = (folder / "exact.cml").read_text()
    late = tmp_path / "late.cml"
    late.write_text(_delay(text, "Ux.1=8\\r\\n", 0.030))
    report = compare_session(late, folder / "hidden.toml")
    (diff,) = report.differences
    assert diff.kind == "timing" and diff.real is not None and diff.real.text == "Ux.1=8"
    assert diff.dt == pytest.approx(-0.030 - 0.0025, abs=0.0015)   # + its wire time, latency
    # 20 ms, plus the wire time at 38400 baud of Ux.1=8\r\n and of the bytes received
    # before it since the last line sent (an echo, a reply: 10 bits a byte)
    wire = diff.tolerance_s - 0.020
    assert 8 * 10 / 38400 <= wire < 0.010 and round(wire * 38400 / 10, 6).is_integer()
    assert (f"earlier on the virtual motor (tolerance {diff.tolerance_s * 1000:.1f} ms)"
            in diff.describe())
    # a wider tolerance lets it pass
    assert compare_session(late, folder / "hidden.toml", Tolerance(time_abs=0.05)).ok


def test_a_line_the_virtual_motor_did_not_say_is_missing(folder: Path, tmp_path: Path) -> None:
    rows = (folder / "exact.cml").read_text().split("\n")
    i = rows.index("<< ?96.1\\r\\n")
    t = float(rows[i - 1][4:-2]) + 0.0005          # after the echo, before the reply
    rows[i + 1:i + 1] = [f"# t={t:.6f} <", "<< error01.1: syntax error!!\\r\\n"]
    odd = tmp_path / "odd.cml"
    odd.write_text("\n".join(rows))
    report = compare_session(odd, folder / "hidden.toml")
    (diff,) = report.differences
    assert diff.kind == "missing" and diff.virtual is None
    assert 'the real motor said "error01.1: syntax error!!"' in diff.describe()


def _stamp_earlier(text: str, line: str, by: float, *, echo: bool) -> str:
    """Move the stamp of every ``line`` sent (and with ``echo`` its echo's) ``by`` s earlier:
    as if the real motor had acted on it ``by`` later than the relay saw its CR go by."""
    rows = text.split("\n")
    for i, row in enumerate(rows):
        if row == line and rows[i - 1].endswith(" >"):
            rows[i - 1] = f"# t={float(rows[i - 1][4:-2]) - by:.6f} >"
            if echo:
                assert rows[i + 1].endswith(" <") and rows[i + 2] == f"<< {line}\\r\\n"
                rows[i + 1] = f"# t={float(rows[i + 1][4:-2]) - by:.6f} <"
    return "\n".join(rows)


def test_polled_values_allow_the_lag_the_echo_shows_ch3_k23_echo(folder: Path,
                                                                 tmp_path: Path) -> None:
    """The real motor acts on a line at its CR and echoes its bytes as they arrive (ch. 3
    K23 8): when the echo of ``^`` came back 4 ms after the relay saw the CR, the move may
    have started up to 4 ms late (a busy host, a USB adapter), and the values polled
    during it pass; when the echo came back at once, the same late values do not."""
    text = (folder / "exact.cml").read_text()
    lagged = tmp_path / "lagged.cml"
    lagged.write_text(_stamp_earlier(text, "^.1", 0.004, echo=False))
    report = compare_session(lagged, folder / "hidden.toml")
    assert report.ok, [v.describe() for v in report.differences[:5]]
    prompt = tmp_path / "prompt.cml"
    prompt.write_text(_stamp_earlier(text, "^.1", 0.004, echo=True))
    report = compare_session(prompt, folder / "hidden.toml")
    late = [v for v in report.differences if v.real is not None and v.band is not None]
    assert len(late) > 20 and {v.kind for v in report.differences} == {"value"}
    # 4 ms at up to 30 000 pps is up to 120 pulses behind the band
    assert all(v.real is not None and v.band is not None and v.real.text.startswith(
        ("Px", "Pe", "Ix")) and v.off > 0 for v in late)


class _Tables(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.rows: dict[str, int] = {}
        self.table = ""
        self.images: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        found = dict(attrs)
        if tag == "table":
            self.table = found.get("id") or ""
            self.rows[self.table] = 0
        elif tag == "tr":
            self.rows[self.table] += 1
        elif tag == "img":
            self.images.append(found.get("src") or "")


def _png_size(data: bytes) -> tuple[int, int]:
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR"
    width, height = struct.unpack(">II", data[16:24])
    return width, height


def test_report_and_plot_files_hold_the_differences(folder: Path, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    from coolmuscle.tools.cli.app import main
    md, html, png = tmp_path / "c.md", tmp_path / "c.html", tmp_path / "c.png"
    with pytest.raises(SystemExit) as info:
        main(["compare", str(folder / "noisy.cml"), "--report", str(md), "--plot", str(png)])
    assert info.value.code == 1
    out = capsys.readouterr().out
    report = compare_session(folder / "noisy.cml")
    n = len(report.differences)
    assert f"coolmuscle: FAIL {n} difference(s) beyond tolerance" in out
    assert "timing: max(20 ms, 2 % of the time since the line sent before it)" in out
    text = md.read_text()
    assert "![real and virtual curves](c.png)" in text
    rows = re.findall(r"^\| (\d+) \| [0-9.]+ \| (different value|extra|missing|different "
                      r"bytes|different timing) \|", text, re.M)
    extras = [v for v in report.differences if v.real is None]
    assert len(rows) == n - len(extras)
    assert ("| different bytes | " in text) and re.search(r"\| equal \| \d+ \|", text)
    # the rows and the counts name a verdict with the same words
    counted = dict(re.findall(r"^\| ([a-z ]+) \| (\d+) \|$", text, re.M))
    for name in {name for _, name in rows}:
        assert int(counted[name]) == sum(1 for _, n in rows if n == name) + (
            len(extras) if name == "extra" else 0), name
    # three panels (Pe, Px, Ix): 1000 x (100 + 3 x 200) pixels
    assert _png_size(png.read_bytes()) == (1000, 700)

    with pytest.raises(SystemExit):
        main(["compare", str(folder / "noisy.cml"), "--report", str(html)])
    capsys.readouterr()
    parser = _Tables()
    parser.feed(html.read_text())
    assert parser.rows["differences"] == n + 1          # the header row
    (image,) = parser.images
    assert image.startswith("data:image/png;base64,")
    assert _png_size(base64.b64decode(image.split(",", 1)[1])) == (1000, 700)


def test_a_passing_compare_exits_0(folder: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from coolmuscle.tools.cli.app import main
    with pytest.raises(SystemExit) as info:
        main(["compare", str(folder / "noisy.cml"), "--machine", str(folder / "hidden.toml")])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert out.rstrip().endswith("line(s) received within tolerance")

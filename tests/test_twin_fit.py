"""``coolmuscle fit`` (docs/twin.md): the hidden machine's load and servo parameters
are recovered from a noisy, quantized capture within 5 %, the fitted machine file then
makes ``compare`` pass, and fits that cannot be done are refused in one line with exit 2
and nothing written."""

from __future__ import annotations

import sys
import tomllib
from pathlib import Path

import pytest

from cli_support import cli
from coolmuscle.chain.machine import load_machine
from coolmuscle.tools.twin.compare import compare_session
from coolmuscle.tools.twin.fit import fit_session
from twin_support import HIDDEN, write_capture

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_capture(tmp_path_factory.mktemp("twin-fit"), seed=7)


def test_fit_recovers_the_hidden_machine_and_compare_then_passes(
        capture: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out, plot = tmp_path / "fitted.toml", tmp_path / "fit.png"
    code, text, err = cli(capsys, "fit", str(capture), "--params", "inertia,friction,kp,cw",
                          "--machine-out", str(out), "--plot", str(plot))
    assert code == 0, err
    axis = tomllib.loads(out.read_text())["axis"][0]
    fitted = {"inertia": axis["load"]["inertia"], "friction": axis["load"]["friction"],
              "kp": axis["drive"]["kp"], "cw": axis["stoppers"]["cw"]}
    for name, hidden in HIDDEN.items():
        assert fitted[name] == pytest.approx(hidden, rel=0.05), name
    # each parameter printed with its standard error and 95 % interval
    for name in ("inertia.1", "friction.1", "kp.1", "cw.1"):
        assert any(line.lstrip().startswith(name) and "standard error" in line
                   and "95 %" in line for line in text.splitlines()), text
    assert "converged after" in text and "weighted residual RMS" in text
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    load_machine(out)
    report = compare_session(capture, out)
    assert report.ok, [v.describe() for v in report.differences[:5]]


def test_the_fit_result_from_python(capture: Path) -> None:
    result = fit_session(capture, params="inertia,kp")
    assert result.rms < result.rms_start
    assert [p.name for p in result.params] == ["inertia.1", "kp.1"]
    assert all(se > 0 for se in result.stderr)
    assert set(result.quantity_rms) == {"Px", "Pe", "Ix"}


@pytest.mark.parametrize("args, message", [
    (["--params", "inertia,viscosity"], "unknown parameter 'viscosity'"),
    (["--params", "inertia.3"], "the chain has motors 1..1"),
    (["--params", "inertia,rotor_inertia"], "only their sum acts"),
    (["--params", "kp", "--max-replays", "2"], "did not converge within 2 replays"),
    (["--params", "ccw"], "ccw.1 is not identifiable from this session: it changes no "
                          "polled value"),
    (["--params", "inertia,friction,rated_torque"], "cannot be told apart"),
])
def test_a_fit_that_cannot_be_done_is_one_line_exit_2_and_nothing_written(
        capture: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str],
        message: str) -> None:
    out = tmp_path / "m.toml"
    code, _, err = cli(capsys, "fit", str(capture), "--machine-out", str(out), *args)
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("coolmuscle: error: ") and message in err
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_bad_files_are_one_line_exit_2(capture: Path, tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[[axis]]\n[axis.load]\nviscosity = 1.0\n")
    out = tmp_path / "m.toml"
    cases = [
        (["fit", str(ROOT / "examples" / "2.1-operation.cml"), "--machine-out", str(out)],
         "not a capture"),
        (["fit", str(capture), "--machine", str(bad), "--machine-out", str(out)],
         "unknown key 'viscosity'"),
        (["compare", str(capture), "--machine", str(bad)], "unknown key 'viscosity'"),
        (["compare", str(tmp_path / "missing.cml")], "cannot read"),
        (["compare", str(capture), "--report", str(tmp_path / "r.pdf")], "--report"),
        (["compare", str(capture), "--plot", str(tmp_path / "no" / "p.png")], "no folder"),
        (["fit", str(capture), "--machine-out", str(tmp_path / "m.json")], "--machine-out"),
    ]
    for args, message in cases:
        code, _, err = cli(capsys, *args)
        assert code == 2, (args, err)
        assert err.count("\n") == 1 and message in err, (args, err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml"]


def test_without_scipy_fit_says_how_to_install_it(capture: Path, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str],
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "scipy", None)      # import scipy raises ImportError
    out = tmp_path / "m.toml"
    code, _, err = cli(capsys, "fit", str(capture), "--machine-out", str(out))
    assert code == 2 and err.count("\n") == 1
    assert err == ("coolmuscle: error: coolmuscle fit needs the 'twin' extra (scipy is not "
                   'installed): pip install "coolmuscle[twin]"\n')
    assert not out.exists()


def test_a_fit_starts_from_a_base_machine_file_and_keeps_its_other_keys(
        capture: Path, tmp_path: Path) -> None:
    base = tmp_path / "base.toml"
    base.write_text('name = "my slide"\n# the slide of line 3\n[[axis]]\nmotor = 1\n'
                    'params = { K27 = 962 }\n[axis.load]\ninertia = 3.5e-5\n'
                    '[axis.stoppers]\ncw = 23400\n')
    result = fit_session(capture, base, "kp,cw")
    text = result.machine_text()
    assert "# the slide of line 3" in text and 'name = "my slide"' in text
    data = tomllib.loads(text)["axis"][0]
    assert data["params"] == {"K27": 962} and data["load"]["inertia"] == 3.5e-5
    assert data["stoppers"]["cw"] == pytest.approx(HIDDEN["cw"], rel=0.001)
    assert result.start == [300.0, 23400.0]

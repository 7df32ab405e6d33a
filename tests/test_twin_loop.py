"""The twin loop end to end, through the real relay, without hardware (docs/twin.md).

A ``coolmuscle sim`` with the hidden machine file of the twin tests (a heavier load,
more friction, a softer position loop, a stopper) stands in for the user's real motor on
TCP.  ``coolmuscle capture`` relays a pseudo-terminal to it, and the identification
session of examples/twin/identify.py plays on that pty with pyserial, in real time, as
a user runs it.  Then, with the commands a user types:

* ``compare`` against the hidden machine finds no difference beyond tolerance;
* ``compare`` against the default machine finds the differences and names them;
* ``fit`` recovers every hidden parameter within 5 %, from the capture as recorded
  (wall-clock jitter, replies quantized to whole pulses) and from a copy whose polled
  values carry one more unit of noise each, and ``compare`` of the capture passes with
  the fitted file.

One capture (about 20 s of wall time) serves every assertion: the module is marked
``realtime``, so its tests share one xdist worker and one capture (tests/conftest.py).

The stand-in must answer as a real motor does (within about a millisecond of each
command: a real motor has its own CPU), not stalled by the test machine: the sim and the relay
run at a real-time priority where ``chrt`` is allowed (CI runs as root), and a capture in
which the stand-in answered a command later than :data:`STAND_IN_LAG_S` is not a real
motor's session: it is taken again (at most :data:`CAPTURE_TRIES` times), and the test
fails with that lag named if every try was stalled.
"""

from __future__ import annotations

import bisect
import random
import re
import shutil
import signal
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from coolmuscle.tools.twin.session import read_session
from fixtures import Program, ServedSim, coolmuscle_env, run_coolmuscle
from twin_support import HIDDEN

ROOT = Path(__file__).resolve().parents[1]
HIDDEN_TOML = ROOT / "examples" / "twin" / "hidden.toml"
IDENTIFY = ROOT / "examples" / "twin" / "identify.py"
ENV = coolmuscle_env()

pytestmark = [pytest.mark.slow, pytest.mark.realtime, pytest.mark.timeout(400)]

#: The longest a stand-in may take to answer a command (the first line back after the
#: command's stamp): a real motor at 38.4 kbps echoes within about 1 ms; compare's timing
#: tolerance is 20 ms (tools/twin/compare.py), so a stall of up to 15 ms leaves the capture
#: a real motor's session within that tolerance.
STAND_IN_LAG_S = 0.015
CAPTURE_TRIES = 4


def coolmuscle(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return run_coolmuscle(*args, timeout=timeout)


def _realtime_prefix() -> list[str]:
    """``chrt -f 20`` where this machine lets us run at a real-time priority, else []."""
    if shutil.which("chrt") is None:
        return []
    allowed = subprocess.run(["chrt", "-f", "20", "true"], capture_output=True)
    return ["chrt", "-f", "20"] if allowed.returncode == 0 else []


def stand_in_lag(session: Path) -> float:
    """The longest time from a command's stamp to the first line back after it (with
    echo on, its echo at the latest), whether or not the next command went out first:
    a stall shows on the command sent into it."""
    capture = read_session(session)
    back = [line.time for line in capture.received]
    lags = []
    for command in capture.sent:
        i = bisect.bisect_left(back, command.time)
        if i < len(back):
            lags.append(back[i] - command.time)
    return max(lags, default=0.0)


def _capture_once(folder: Path) -> Path:
    """Play the identification plan through ``coolmuscle capture`` to a hidden-machine sim."""
    procs: list[Program] = []
    rt = _realtime_prefix()
    try:
        sim = ServedSim(folder / "sim.log", "--machine", str(HIDDEN_TOML), prefix=rt,
                        ready_timeout=60)
        procs.append(sim)
        link = folder / "motor"
        session = folder / "session.cml"
        relay = Program(["capture", sim.url, "--pty", str(link), "--out", str(session)],
                        folder / "capture.log", prefix=rt)
        procs.append(relay)
        relay.wait_for(r"capture ready", 60)
        played = subprocess.run([sys.executable, str(IDENTIFY), str(link), "--push-to",
                                 "25000"], capture_output=True, text=True, timeout=120,
                                env=ENV)
        assert played.returncode == 0, played.stderr
        assert relay.signal(signal.SIGINT, 30) == 130, relay.text
        return session
    finally:
        for proc in reversed(procs):
            proc.close()


@pytest.fixture(scope="module")
def captured(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A session of the identification plan, captured through the relay from the sim,
    in which the stand-in answered every command as promptly as a real motor."""
    lags = []
    for _ in range(CAPTURE_TRIES):
        session = _capture_once(tmp_path_factory.mktemp("twin-loop"))
        lags.append(stand_in_lag(session))
        if lags[-1] <= STAND_IN_LAG_S:
            return session
    raise AssertionError(f"the test machine stalled the stand-in motor in every capture: "
                         f"it answered a command up to {max(lags) * 1000:.1f} ms late "
                         f"(a real motor within ~1 ms); lags {lags}")


def _noisy_copy(session: Path, out: Path, seed: int = 25) -> Path:
    """The capture with every polled value (``Px``, ``Pe``, ``Ix`` ...) off by -1, 0 or +1:
    a real encoder and current sense beside the quantization the replies already have."""
    rng = random.Random(seed)
    rows = session.read_text(encoding="utf-8").split("\n")
    for i, row in enumerate(rows):
        m = re.fullmatch(r"<< ([A-Z][a-z]\.1=)(-?\d+)(\\r\\n)", row)
        if m is None or m.group(1) not in ("Px.1=", "Pe.1=", "Ix.1="):
            continue
        old = m.group(1) + m.group(2)
        new = m.group(1) + str(int(m.group(2)) + rng.choice((-1, 0, 1)))
        rows[i] = f"<< {new}{m.group(3)}"
        for j in range(i - 1, max(i - 3, -1), -1):     # its @until, above its stamp
            if rows[j].startswith(f"@until ^{re.escape(old)}$ "):
                rows[j] = rows[j].replace(re.escape(old), re.escape(new), 1)
                break
    out.write_text("\n".join(rows), encoding="utf-8")
    return out


def test_the_capture_is_complete_and_compares_equal_with_the_hidden_machine(
        captured: Path) -> None:
    text = captured.read_text(encoding="utf-8")
    assert text.startswith("# coolmuscle capture: port=socket://127.0.0.1:")
    assert re.search(r"^# end: .*stopped=ctrl-c", text, re.M)
    polls = len(re.findall(r"^<< (?:Px|Pe|Ix)\.1=", text, re.M))
    assert polls > 1000                              # the plan polls every 10 ms
    done = coolmuscle("compare", str(captured), "--machine", str(HIDDEN_TOML))
    assert done.returncode == 0, done.stdout + done.stderr
    assert "different bytes 0, different timing 0, missing 0, extra 0" in done.stdout


def test_against_the_default_machine_compare_names_the_differences(
        captured: Path, tmp_path: Path) -> None:
    report = tmp_path / "report.md"
    done = coolmuscle("compare", str(captured), "--report", str(report))
    assert done.returncode == 1, done.stdout + done.stderr
    assert re.search(r"FAIL \d+ difference\(s\) beyond tolerance", done.stdout + done.stderr)
    body = report.read_text(encoding="utf-8")
    # the softer loop lags more while cruising (Pe = speed / kp) and the heavier,
    # stickier load takes more current (Ix): both are named with their lines
    assert re.search(r"Pe\.1=", body) and re.search(r"Ix\.1=", body)


@pytest.mark.parametrize("noise", [False, True], ids=["as-captured", "one-unit-noise"])
def test_fit_recovers_the_hidden_machine_and_compare_then_passes(
        captured: Path, tmp_path: Path, noise: bool) -> None:
    session = _noisy_copy(captured, tmp_path / "noisy.cml") if noise else captured
    fitted = tmp_path / "fitted.toml"
    done = coolmuscle("fit", str(session), "--machine-out", str(fitted), "--params",
                      "inertia,friction,kp,cw")
    assert done.returncode == 0, done.stdout + done.stderr
    axis = tomllib.loads(fitted.read_text(encoding="utf-8"))["axis"][0]
    got = {"inertia": axis["load"]["inertia"], "friction": axis["load"]["friction"],
           "kp": axis["drive"]["kp"], "cw": axis["stoppers"]["cw"]}
    for name, hidden in HIDDEN.items():
        assert got[name] == pytest.approx(hidden, rel=0.05), (name, got, done.stdout)
        # the printed 95 % interval (standard error and the replies' resolution) holds it
        lo, hi = re.search(rf"^  {name}\.1 += .*95 % (\S+) \.\. (\S+);", done.stdout,
                           re.M).groups()
        assert float(lo) <= hidden <= float(hi), (name, lo, hi)
    # the fitted machine stands in for the real one: the capture compares equal with it
    again = coolmuscle("compare", str(captured), "--machine", str(fitted))
    assert again.returncode == 0, again.stdout + again.stderr

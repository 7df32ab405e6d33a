"""The twin's fit: seconds for a 60 s capture, replays per second, beside one plain run.

Run: ``python bench/bench_fit.py`` (virtual environment active; about a minute).

A 65 s capture of examples/twin/identify.py (six rounds of its moves and the push)
is made on the hidden machine of tests/twin_support.py, with noise.  Measured side by
side in one run: one plain ``coolmuscle run`` of the capture as a script (the same
session through the runner, in process: ``run_script``), one replay of it as the fit
does (:func:`coolmuscle.tools.twin.replay.replay`), one ``compare`` (replay with the
trace recorder, judging every line), and the whole ``fit`` of inertia, friction, kp and
the stopper: seconds, replays, replays per second, and how far each parameter landed
from the hidden value.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from coolmuscle.chain.daisy import Chain  # noqa: E402
from coolmuscle.chain.machine import parse_machine  # noqa: E402
from coolmuscle.tools.script import run_script  # noqa: E402
from coolmuscle.tools.twin.compare import compare  # noqa: E402
from coolmuscle.tools.twin.fit import fit  # noqa: E402
from coolmuscle.tools.twin.params import parse_params  # noqa: E402
from coolmuscle.tools.twin.replay import replay  # noqa: E402
from coolmuscle.tools.twin.session import read_session  # noqa: E402
from twin_support import HIDDEN, HIDDEN_TOML, capture_text, identify  # noqa: E402


def _best(call: object, repeat: int = 3) -> float:
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        call()  # type: ignore[operator]
        best = min(best, time.perf_counter() - start)
    return best


def main() -> None:
    plan = identify().plan(0.01, 6, 25000)          # 65 s
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "session60.cml"
        path.write_text(capture_text(plan, seed=11), encoding="utf-8")
        session = read_session(path)
        path.write_text(capture_text(plan, seed=11, noise=False), encoding="utf-8")
        exact = read_session(path)
    hidden = parse_machine(HIDDEN_TOML, "hidden.toml")
    print(f"capture: {session.duration:.1f} s, {len(session.sent)} lines sent, "
          f"{len(session.received)} received, {len(session.polls)} polled values")

    def plain_run() -> None:        # coolmuscle run session.cml --check --machine hidden.toml
        chain = Chain(machine=hidden)
        try:
            result = run_script(exact.script, chain)
        finally:
            chain.close()
        assert result.ok, result.summary()

    run_s = _best(plain_run)
    replay_s = _best(lambda: replay(session))
    compare_s = _best(lambda: compare(session, replay(session, record=True)), repeat=1)
    params = parse_params("inertia,friction,kp,cw", 1, {1})
    start = time.perf_counter()
    result = fit(session, None, params)
    fit_s = time.perf_counter() - start
    print(f"{'one run --check':<28} {run_s:7.3f} s   {session.duration / run_s:7.0f}x "
          "real time")
    print(f"{'one replay (fit)':<28} {replay_s:7.3f} s   {1 / replay_s:7.2f} replays/s "
          f"({replay_s / run_s:.2f}x the run)")
    print(f"{'compare':<28} {compare_s:7.3f} s   ({compare_s / run_s:.2f}x the run)")
    print(f"{'fit (4 parameters)':<28} {fit_s:7.3f} s   {result.replays} replays, "
          f"{result.replays / fit_s:.2f} replays/s ({fit_s / run_s:.0f}x the run)")
    for p, value in zip(params, result.values, strict=True):
        hidden = HIDDEN[p.kind.key]
        off = 100 * (value / hidden - 1)
        print(f"  {p.name:<11} {value:.6g} (hidden {hidden:g}: {off:+.2f} %)")


if __name__ == "__main__":
    main()

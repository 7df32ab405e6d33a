"""Crash safety of `$`: SIGKILL a saving process at random instants, 100 times.

A child process opens the store and saves snapshot after snapshot (as a host
sending ``$.1`` in a loop would), printing each generation once its save has
returned.  Each snapshot is self-describing: it carries its generation number and
a checksum of its contents, and its contents are a pure function of the
generation.  After every kill the store must pass ``PRAGMA integrity_check`` and
hold exactly the last acknowledged snapshot or the one that was being written.
"""

from __future__ import annotations

import os
import random
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from coolmuscle.motor.state.store import Store

ROUNDS = 100

CHILD = r'''
import hashlib, json, sys

def make_snapshot(generation):
    """Contents depend only on the generation; ~40 kB of JSON."""
    g = generation
    params = {k: (g * 7 + k) % 5 for k in range(20, 90)}
    memory = {"P": [(g * 31 + i) % 100000 for i in range(201)],
              "V": [{"s": "g%03d" % (g % 1000)}] + [g + i for i in range(15)]}
    banks = {str(b): ["S%d.1, A%d.1, P%d.1 // gen %d line %d" % (b % 15 + 1, b % 8 + 1, i, g, i)
                      for i in range(1, 12 + (g + b) % 9)] for b in range(1, 31)}
    body = {"generation": g, "params": params, "memory": memory, "banks": banks,
            "ladders": {"1": ["V1.1=V1.1+%d" % g, "END"]}}
    text = json.dumps(body, sort_keys=True)
    body["checksum"] = hashlib.sha256(text.encode()).hexdigest()
    return body

def checksum_ok(snapshot):
    body = {k: v for k, v in snapshot.items() if k != "checksum"}
    body["params"] = {str(k): v for k, v in body["params"].items()}
    text = json.dumps(body, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest() == snapshot["checksum"]

if __name__ == "__main__":
    from coolmuscle.motor.state.store import Store
    store = Store(sys.argv[1])
    generation = int(sys.argv[2])
    print("ready", flush=True)
    while True:
        generation += 1
        store.save_snapshot(1, make_snapshot(generation))
        print(generation, flush=True)
'''


def _helpers() -> dict:
    namespace: dict = {"__name__": "crash_child"}
    exec(compile(CHILD, "crash_child", "exec"), namespace)  # noqa: S102 - our own text
    return namespace


def _run_round(script: Path, db: Path, start: int, rng: random.Random) -> list[int]:
    """Start a saver, kill it at a random instant, return the acknowledged generations."""
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).parents[1] / "src"))
    child = subprocess.Popen([sys.executable, str(script), str(db), str(start)],
                             stdout=subprocess.PIPE, env=env, text=True)
    assert child.stdout is not None
    early: list[str] = []
    try:
        if rng.random() < 0.15:
            time.sleep(rng.uniform(0.0, 0.08))      # maybe while opening the store
        else:
            # somewhere in the save loop, after a few saves: counted in the saver's own
            # pace, so a busy machine does not turn every round into a kill at start-up
            assert child.stdout.readline().strip() == "ready"
            early = [child.stdout.readline() for _ in range(rng.randint(1, 3))]
            time.sleep(rng.uniform(0.0, 0.04))
        child.send_signal(signal.SIGKILL)
        out = "".join(early) + child.stdout.read()
    finally:
        child.kill()
        child.wait()
    assert child.returncode == -signal.SIGKILL
    return [int(line) for line in out.split() if line.isdigit()]


def _integrity(db: Path) -> str:
    conn = sqlite3.connect(db)
    try:
        return conn.execute("PRAGMA integrity_check").fetchone()[0]
    finally:
        conn.close()


@pytest.mark.slow
@pytest.mark.timeout(90)
def test_store_survives_sigkill_during_dollar_saves(tmp_path: Path) -> None:
    helpers = _helpers()
    make_snapshot, checksum_ok = helpers["make_snapshot"], helpers["checksum_ok"]
    script = tmp_path / "saver.py"
    script.write_text(CHILD)
    db = tmp_path / "state" / "store.sqlite3"
    rng = random.Random(20260511)
    current = 0                    # generation the store holds (0: nothing yet)
    mid_save_kills = 0
    for round_no in range(ROUNDS):
        acked = _run_round(script, db, current, rng)
        if db.exists():
            assert _integrity(db) == "ok", f"round {round_no}"
        last_acked = acked[-1] if acked else current
        with Store(db) as store:
            loaded = store.load(1)
        if loaded is None:
            assert last_acked == 0, f"round {round_no}: acknowledged save lost"
            continue
        generation = loaded["generation"]
        assert generation in (last_acked, last_acked + 1), (round_no, generation, last_acked)
        assert checksum_ok(loaded), f"round {round_no}: torn snapshot"
        assert loaded == make_snapshot(generation), f"round {round_no}: not a written snapshot"
        mid_save_kills += generation == last_acked + 1
        current = generation
    assert current > ROUNDS, "the saver hardly ever got to save"
    print(f"{ROUNDS} kills, {current} snapshots, {mid_save_kills} commits unacknowledged")

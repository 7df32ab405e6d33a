"""Saved state is validated; the XDG rule for the state dir.

A store whose ``$`` snapshot (cml-users-guide.txt 2.1.2) or automatic K save
(ch. 3) holds something the motor never writes stops start-up with one line that
names the file, the entry and how to recover; a 0-byte store is refused, never
silently replaced by defaults.  A relative ``XDG_DATA_HOME`` is ignored (XDG base
directory spec).  ``coolmuscle sim`` runs as a real subprocess.
"""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
from pathlib import Path

import pytest

from coolmuscle.chain.daisy import Chain
from coolmuscle.errors import StoreError
from coolmuscle.motor.state.store import Store
from coolmuscle.tools.cli import app as cli
from fixtures import ChainFactory, SimFactory, coolmuscle_env, run_coolmuscle

ENV = coolmuscle_env(COLUMNS="300")


def make_store(state: Path) -> Path:
    chain = Chain(state_dir=state)
    chain.execute("P1.1=5")
    chain.execute("$.1")
    chain.execute("K37.1=1")
    chain.close()
    return state / "coolmuscle.sqlite3"


def edit_snapshot(path: Path, change: dict) -> None:
    conn = sqlite3.connect(path)
    data = json.loads(conn.execute("SELECT data FROM snapshot WHERE motor_id=1").fetchone()[0])
    data.update(change)
    conn.execute("UPDATE snapshot SET data=? WHERE motor_id=1", (json.dumps(data),))
    conn.commit()
    conn.close()


def start_sim(state: Path) -> subprocess.CompletedProcess[str]:
    """``sim --tcp 0 --state STATE`` that is expected to refuse to start."""
    return run_coolmuscle("sim", "--tcp", "0", "--state", str(state), timeout=30, env=ENV)


CORRUPTIONS = {
    "param-text": ({"params": {"20": "abc"}}, "K20='abc'"),
    "param-list": ({"params": {"20": [1, 2]}}, "K20=[1, 2]"),
    "bank-list": ({"banks": {"program": [["S.1=1"]]}}, "banks 'program' is a list"),
    "bank-string": ({"banks": {"program": {"1": "S.1=1"}}}, "program bank 1"),
    "memory-string": ({"memory": "P1=5"}, "'memory' is a str"),
}


@pytest.mark.parametrize("case", sorted(CORRUPTIONS))
def test_corrupted_snapshot_names_file_entry_and_recovery(tmp_path: Path, case: str) -> None:
    change, entry = CORRUPTIONS[case]
    path = make_store(tmp_path)
    edit_snapshot(path, change)
    out = start_sim(tmp_path)
    assert out.returncode == 1, out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in out.stderr, out.stderr
    assert str(path) in lines[0] and entry in lines[0] and "move the file aside" in lines[0]


def test_overlay_of_another_type_names_file_and_entry(tmp_path: Path) -> None:
    path = make_store(tmp_path)
    conn = sqlite3.connect(path)
    conn.execute("UPDATE param SET value='abc' WHERE motor_id=1 AND k=37")
    conn.commit()
    conn.close()
    with pytest.raises(StoreError, match=r"K37='abc'.*move the file aside"):
        Store(path).load(1)
    out = start_sim(tmp_path)
    assert out.returncode == 1 and str(path) in out.stderr and "K37" in out.stderr, out.stderr


def test_a_zero_byte_store_is_refused_not_replaced(tmp_path: Path) -> None:
    path = tmp_path / "coolmuscle.sqlite3"
    path.write_bytes(b"")
    out = start_sim(tmp_path)
    assert out.returncode == 1, out.stderr
    assert str(path) in out.stderr and "0 bytes" in out.stderr and "move" in out.stderr
    assert path.stat().st_size == 0          # left as found


def test_a_new_store_appears_whole(tmp_path: Path) -> None:
    with Store(tmp_path / "new.sqlite3") as store:
        assert store.load(1) is None
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith("new")) == \
        ["new.sqlite3"]


def test_a_relative_xdg_data_home_is_ignored(monkeypatch: pytest.MonkeyPatch,
                                             tmp_path: Path) -> None:
    monkeypatch.setenv("XDG_DATA_HOME", "relative/data")
    monkeypatch.setenv("HOME", str(tmp_path))
    assert cli.default_state_dir() == tmp_path / ".local/share/coolmuscle/state"
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "abs"))
    assert cli.default_state_dir() == tmp_path / "abs/coolmuscle/state"


def test_one_chain_per_state_directory_in_one_process(
        tmp_path: Path, make_chain: ChainFactory) -> None:
    """Two chains saving into one store would overwrite each other's snapshots (each `$`
    writes the whole motor): the second is refused while the first is open, with the
    holder's pid, and gets the state once the first has closed."""
    first = make_chain(state_dir=tmp_path)
    first.execute("K42.1=111")
    first.execute("P5.1=555")
    assert first.execute("$.1") == ["saved.1"]
    with pytest.raises(StoreError, match=rf"in use: another coolmuscle \(pid {os.getpid()}\)"):
        make_chain(state_dir=tmp_path)
    first.close()
    second = make_chain(state_dir=tmp_path)
    assert second.execute("K42.1") == ["K42.1=111"] and second.execute("P5.1") == ["P5.1=555"]
    second.close()
    with Store(tmp_path / "coolmuscle.sqlite3") as reader:    # readers are never refused
        assert reader.integrity_check() == "ok"


def test_a_second_sim_on_the_same_state_is_refused_and_the_first_keeps_saving(
        tmp_path: Path, served_sim: SimFactory, make_chain: ChainFactory) -> None:
    """Two ``coolmuscle sim --state DIR``: the second ends at once with one line and
    exit 1; what the first saved (an automatic K save and a ``$``) is there after it
    stops.  (An attack found both answering ``saved.1`` and the first's saves lost.)"""
    import socket
    first = served_sim(state=tmp_path, env=ENV)
    second = start_sim(tmp_path)
    assert second.returncode == 1, second.stderr
    lines = second.stderr.strip().splitlines()
    assert len(lines) == 1 and "is in use: another coolmuscle" in lines[0], lines
    assert f"pid {first.pid}" in lines[0] and "Traceback" not in second.stderr
    with socket.create_connection(("127.0.0.1", first.port), timeout=5) as sock:
        sock.sendall(b"K42.1=111\r\nP5.1=555\r\n$.1\r\n")
        got = b""
        while b"saved.1" not in got:
            chunk = sock.recv(1024)
            assert chunk, got
            got += chunk
    assert first.stop(signal.SIGTERM, 30) == 0
    chain = make_chain(state_dir=tmp_path)
    assert chain.execute("K42.1") == ["K42.1=111"] and chain.execute("P5.1") == ["P5.1=555"]


def test_a_snapshot_nested_deeper_than_json_decodes_is_one_line_and_kept(
        tmp_path: Path, make_chain: ChainFactory) -> None:
    """A `$` snapshot replaced by 100,000 nested arrays: the documented one-line
    "unreadable ... move the file aside" StoreError (it was an internal error:
    RecursionError), and the file is left as it was."""
    chain = make_chain(state_dir=tmp_path)
    assert chain.execute("$.1") == ["saved.1"]
    chain.close()
    path = tmp_path / "coolmuscle.sqlite3"
    with sqlite3.connect(path) as db:
        db.execute("UPDATE snapshot SET data = ?", ("[" * 100_000 + "]" * 100_000,))
    before = path.read_bytes()
    with pytest.raises(StoreError, match=r"unreadable \(nested too deeply\); move the file"):
        make_chain(state_dir=tmp_path)
    assert path.read_bytes() == before


@pytest.mark.parametrize("target_kind", ["file", "dangling"])
def test_a_symlink_at_the_lock_file_is_refused_and_its_target_untouched(
        tmp_path: Path, make_chain: ChainFactory, target_kind: str) -> None:
    """``DIR/coolmuscle.sqlite3.lock`` as a symbolic link: start-up truncated its
    target and wrote a PID there.  Now it is refused in one line that names the link,
    the target keeps its bytes (or stays absent) and the store is not opened."""
    state = tmp_path / "state"
    state.mkdir()
    target = tmp_path / "precious.txt"
    if target_kind == "file":
        target.write_bytes(b"keep me\n")
    (state / "coolmuscle.sqlite3.lock").symlink_to(target)
    with pytest.raises(StoreError) as refused:
        make_chain(state_dir=state)
    message = str(refused.value)
    assert "coolmuscle.sqlite3.lock is a symbolic link" in message and "\n" not in message
    if target_kind == "file":
        assert target.read_bytes() == b"keep me\n"
    else:
        assert not target.exists()
    assert not (state / "coolmuscle.sqlite3").exists()


def test_a_lock_file_that_is_not_a_regular_file_is_refused(tmp_path: Path) -> None:
    """A FIFO or a directory at the lock file's name: one line, nothing written."""
    fifo_dir, dir_dir = tmp_path / "fifo", tmp_path / "dir"
    fifo_dir.mkdir()
    dir_dir.mkdir()
    os.mkfifo(fifo_dir / "store.sqlite3.lock")
    (dir_dir / "store.sqlite3.lock").mkdir()
    with pytest.raises(StoreError, match=r"store.sqlite3.lock is a FIFO, not the store's lock"):
        Store(fifo_dir / "store.sqlite3", writer=True)
    with pytest.raises(StoreError, match=r"store.sqlite3.lock is a directory, not the store"):
        Store(dir_dir / "store.sqlite3", writer=True)
    assert not (fifo_dir / "store.sqlite3").exists()


def test_a_symlinked_lock_file_stops_the_sim_in_one_line(tmp_path: Path) -> None:
    state = tmp_path / "state"
    state.mkdir()
    target = tmp_path / "precious.txt"
    target.write_bytes(b"keep me\n")
    (state / "coolmuscle.sqlite3.lock").symlink_to(target)
    done = start_sim(state)
    assert done.returncode == 1, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "is a symbolic link, not the store's lock file" in lines[0]
    assert target.read_bytes() == b"keep me\n"

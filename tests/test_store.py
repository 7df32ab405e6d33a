"""The persistent store: `$` snapshots, automatic K persistence, bad files."""

from __future__ import annotations

import os
import shutil
import sqlite3
import tempfile
from pathlib import Path

import pytest

from coolmuscle.errors import DamagedStoreError, StoreError
from coolmuscle.motor.state.firmware import CM2
from coolmuscle.motor.state.memory import Memory
from coolmuscle.motor.state.param_table import ParamTable
from coolmuscle.motor.state.store import (
    APPLICATION_ID,
    DEFAULT_FILENAME,
    SCHEMA_VERSION,
    Store,
    default_state_dir,
    set_aside,
)


@pytest.fixture
def path(tmp_path: Path) -> Path:
    return tmp_path / "state" / "store.sqlite3"


@pytest.fixture
def store(path: Path) -> Store:
    with Store(path) as s:
        yield s


def snapshot(**changes: object) -> dict:
    params = ParamTable()
    memory = Memory(CM2)
    memory.set("P", 1, 10000)
    memory.set("V", 1, "Px")
    snap = {"firmware": "cm2", "params": params.values(), "memory": memory.to_dict(),
            "banks": {"1": ["S1.1, A1.1, P1.1", "T1.1", "P2.1"]},
            "ladders": {"1": ["V1.1> V2.1, S.1= S1.1, S.1= S2.1"]}}
    snap.update(changes)
    return snap


def test_default_state_dir_follows_xdg(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    assert default_state_dir() == tmp_path / "xdg" / "coolmuscle"
    monkeypatch.delenv("XDG_DATA_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert default_state_dir() == tmp_path / "home" / ".local" / "share" / "coolmuscle"
    monkeypatch.setenv("XDG_DATA_HOME", "relative/dir")   # ignored per XDG spec
    assert default_state_dir() == tmp_path / "home" / ".local" / "share" / "coolmuscle"


def test_default_path_is_created(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    with Store() as s:
        assert s.path == str(tmp_path / "xdg" / "coolmuscle" / DEFAULT_FILENAME)
        s.save_param(1, 20, 1)
    assert (tmp_path / "xdg" / "coolmuscle" / DEFAULT_FILENAME).is_file()


def test_snapshot_round_trip_exact(store: Store) -> None:
    snap = snapshot()
    assert store.save_snapshot(1, snap) == 1
    loaded = store.load(1)
    assert loaded == snap
    assert all(isinstance(k, int) for k in loaded["params"])
    memory = Memory.from_dict(CM2, loaded["memory"])
    assert memory.get("P", 1) == 10000


def test_nothing_saved_loads_none(store: Store) -> None:
    assert store.load(2) is None
    assert store.motors() == []


def test_k_changes_persist_without_dollar(store: Store) -> None:
    store.save_param(3, 70, 0)
    store.save_param(3, 20, 4)
    store.save_param(3, 20, 5)
    assert store.load(3) == {"params": {20: 5, 70: 0}}
    assert store.motors() == [3]


def test_power_cycle_applies_k_overlay_to_snapshot(path: Path) -> None:
    with Store(path) as s:
        s.save_snapshot(1, snapshot())
        s.save_param(1, 70, 0)
    with Store(path) as s:                 # "power cycle"
        loaded = s.load(1)
    assert loaded["params"][70] == 0
    assert loaded["params"][20] == 0
    expected = snapshot()
    expected["params"][70] = 0
    assert loaded == expected


def test_dollar_folds_the_overlay_in(store: Store) -> None:
    store.save_param(1, 70, 0)
    snap = snapshot()                      # carries K70=1, the current value
    assert store.save_snapshot(1, snap) == 1
    assert store.load(1) == snap
    assert store.save_snapshot(1, snapshot(banks={})) == 2


def test_motors_are_independent(store: Store) -> None:
    store.save_snapshot(1, snapshot(firmware="cm2"))
    store.save_snapshot(2, snapshot(firmware="rt3"))
    store.save_param(2, 20, 1)
    assert store.load(1)["params"][20] == 0
    assert store.load(2)["params"][20] == 1
    assert store.motors() == [1, 2]
    store.delete(2)
    assert store.load(2) is None and store.motors() == [1]


def test_wal_and_full_sync(store: Store, path: Path) -> None:
    conn = sqlite3.connect(path)
    try:
        assert conn.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        assert conn.execute("PRAGMA application_id").fetchone()[0] == APPLICATION_ID
        assert conn.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION
    finally:
        conn.close()
    assert store._connection().execute("PRAGMA synchronous").fetchone()[0] == 2  # FULL
    assert store.integrity_check() == "ok"


def test_bad_arguments(store: Store) -> None:
    for bad_id in (0, 16, -1, "1", True):
        with pytest.raises(ValueError):
            store.save_snapshot(bad_id, {})  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        store.save_param(1, 20, 1.5)  # type: ignore[arg-type]
    for bad in ({"x": (1, 2)}, {"x": {1: 2}}, {"x": float("nan")}, {"x": {1, 2}}, [1]):
        with pytest.raises(ValueError):
            store.save_snapshot(1, bad)  # type: ignore[arg-type]
    assert store.load(1) is None


def test_closed_store_raises_store_error(path: Path) -> None:
    s = Store(path)
    s.close()
    s.close()
    with pytest.raises(StoreError):
        s.load(1)


def test_text_file_is_not_a_store(tmp_path: Path) -> None:
    bad = tmp_path / "notes.txt"
    bad.write_text("this is not a database\n" * 100)
    with pytest.raises(StoreError, match="not a usable coolmuscle store"):
        Store(bad)


def test_a_damaged_store_is_set_aside_whole_but_never_under_a_writer(tmp_path: Path) -> None:
    """What ``sim --reset`` does with a file nothing can be read from: it moves it (and
    its -wal / -shm) aside under a free name, only when no running chain holds it."""
    bad = tmp_path / "coolmuscle.sqlite3"
    for content in (b"junk" * 300, b""):
        bad.write_bytes(content)
        (tmp_path / "coolmuscle.sqlite3-wal").write_bytes(b"wal")
        with pytest.raises(DamagedStoreError) as caught:
            Store(bad)
        assert caught.value.problem in ("is not a usable coolmuscle store: file is not a "
                                        "database", "is empty (0 bytes), not a coolmuscle "
                                        "store")
        assert f"mv {bad} {bad}.bad" in str(caught.value)
    assert set_aside(bad) == f"{bad}.bad"
    assert (tmp_path / "coolmuscle.sqlite3.bad-wal").read_bytes() == b"wal"
    assert not bad.exists() and not (tmp_path / "coolmuscle.sqlite3-wal").exists()
    Store(bad).close()                                    # a new store starts there
    bad.write_bytes(b"junk" * 300)
    assert set_aside(bad) == f"{bad}.bad.1"
    with Store(tmp_path / "held.sqlite3", writer=True):
        with pytest.raises(StoreError, match="in use"):
            set_aside(tmp_path / "held.sqlite3")
    assert (tmp_path / "held.sqlite3").exists()


def test_foreign_sqlite_file_is_refused(tmp_path: Path) -> None:
    other = tmp_path / "other.db"
    conn = sqlite3.connect(other)
    conn.execute("CREATE TABLE t (x)")
    conn.commit()
    conn.close()
    with pytest.raises(StoreError, match="not a coolmuscle store"):
        Store(other)


def test_newer_schema_is_refused(path: Path) -> None:
    Store(path).close()
    conn = sqlite3.connect(path)
    conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    conn.commit()
    conn.close()
    with pytest.raises(StoreError, match="not supported"):
        Store(path)


def test_damaged_page_is_reported(path: Path) -> None:
    with Store(path) as s:
        for motor in range(1, 16):
            s.save_snapshot(motor, snapshot())
    conn = sqlite3.connect(path)
    conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    conn.close()
    raw = bytearray(path.read_bytes())
    page = 4096
    for offset in range(2 * page, len(raw), page):
        raw[offset:offset + 64] = b"\xa5" * 64       # scribble over page headers
    path.write_bytes(bytes(raw))
    with pytest.raises(StoreError):
        with Store(path) as s:
            for motor in range(1, 16):
                s.load(motor)


def test_unreadable_snapshot_row_is_store_error(store: Store, path: Path) -> None:
    store.save_snapshot(1, snapshot())
    conn = sqlite3.connect(path)
    conn.execute("UPDATE snapshot SET data = '{broken' WHERE motor_id = 1")
    conn.commit()
    conn.close()
    with pytest.raises(StoreError, match="unreadable"):
        store.load(1)


def _opens_as_store_error(path: Path) -> bool:
    try:
        Store(path)
    except StoreError:
        return True
    return False


def test_unwritable_directory() -> None:
    """A directory the user may not write to is a StoreError (as root: a child that
    drops to the 'nobody' user, since root ignores directory permissions)."""
    base = Path(tempfile.mkdtemp())
    base.chmod(0o755)
    locked = base / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    target = locked / "sub" / "store.sqlite3"
    try:
        if os.geteuid() != 0:
            assert _opens_as_store_error(target)
            return
        pid = os.fork()
        if pid == 0:                      # child: become nobody, try, report by exit code
            code = 2
            try:
                os.setgid(65534)
                os.setuid(65534)
                code = 0 if _opens_as_store_error(target) else 1
            finally:
                os._exit(code)
        _, status = os.waitpid(pid, 0)
        assert os.waitstatus_to_exitcode(status) == 0
    finally:
        locked.chmod(0o755)
        shutil.rmtree(base)


def test_state_dir_that_is_a_file(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(StoreError, match="state directory"):
        Store(blocker / "store.sqlite3")

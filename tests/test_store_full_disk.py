"""The store on a full disk (a small tmpfs the test mounts and always unmounts).

``$`` (cml-users-guide.txt 2.1.2) on a full disk tells the host ``not saved.n: ...``
instead of ``saved.n``; a K write (ch. 3 "saved automatically") that cannot be
stored is told too and holds in memory; what was saved before is never lost.
"""

from __future__ import annotations

import logging
import os
import subprocess
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from coolmuscle.chain.daisy import Chain
from coolmuscle.errors import StoreError
from fixtures import ChainFactory, coolmuscle_env, run_coolmuscle


@pytest.fixture
def small_disk(tmp_path: Path) -> Iterator[Path]:
    if os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root (CI runs as root)")
    mount = tmp_path / f"harden-disk-{uuid.uuid4().hex[:8]}"
    mount.mkdir()
    subprocess.run(["mount", "-t", "tmpfs", "-o", "size=512k", "tmpfs", str(mount)], check=True)
    try:
        yield mount
    finally:
        subprocess.run(["umount", "-l", str(mount)], check=False)
        mount.rmdir()


def fill(directory: Path) -> None:
    """Write until the file system is full."""
    fd = os.open(directory / "filler", os.O_WRONLY | os.O_CREAT, 0o600)
    try:
        while True:
            os.write(fd, b"\0" * 4096)
    except OSError:
        pass
    finally:
        os.close(fd)


def test_full_disk_is_told_and_loses_nothing_saved(
        small_disk: Path, caplog: pytest.LogCaptureFixture, make_chain: ChainFactory) -> None:
    chain = make_chain(state_dir=small_disk)
    host: list[bytes] = []
    chain.host_line.add_listener(host.append)
    chain.host_line.feed(b"K23.1=16\rP1.1=111\r$.1\r")
    assert b"saved.1" in b"".join(host)
    fill(small_disk)
    host.clear()
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        chain.host_line.feed(b"P1.1=222\r" + b"P%d.1=5\r" % 2 + b"$.1\r")
        for i in range(3, 200):           # make the snapshot bigger than what is left
            chain.execute(f"P{i}.1=123456789")
        chain.host_line.feed(b"$.1\r")
        chain.host_line.feed(b"K37.1=1\r")
    out = b"".join(host).decode()
    assert "not saved.1:" in out and "full" in out
    assert "saved.1\r" not in out.replace("not saved.1", "")
    assert "K37.1 not stored:" in out
    assert all(r.exc_info is None for r in caplog.records), "a traceback was logged"
    assert chain.get_param(1, 37) == 1                 # holds in memory
    chain.close()
    os.unlink(small_disk / "filler")
    again = make_chain(state_dir=small_disk)           # power cycle: the last good $
    try:
        assert again.get_register(1, "P", 1) == 111
        assert again.get_param(1, 23) == 16
    finally:
        again.close()


def test_full_disk_at_start_with_a_healthy_store_says_the_disk_is_full(
        small_disk: Path, make_chain: ChainFactory) -> None:
    """A healthy store on a disk that filled up while the simulator was stopped:
    start-up says the disk is full, not "not a usable coolmuscle store: disk I/O
    error" (which invites moving a good store aside); once there is room again the
    store opens with what was saved."""
    chain = make_chain(state_dir=small_disk)
    assert chain.execute("P1.1=111") == [] and chain.execute("$.1") == ["saved.1"]
    chain.close()
    for leftover in ("coolmuscle.sqlite3-wal", "coolmuscle.sqlite3-shm"):
        assert not (small_disk / leftover).exists()
    fill(small_disk)
    with pytest.raises(StoreError) as refused:
        make_chain(state_dir=small_disk)
    message = str(refused.value)
    assert "the disk is full" in message and "not a usable" not in message, message
    assert "\n" not in message
    os.unlink(small_disk / "filler")
    again = make_chain(state_dir=small_disk)
    assert again.get_register(1, "P", 1) == 111
    again.close()


def test_full_disk_at_start_stops_the_sim_in_one_line(small_disk: Path) -> None:
    chain = Chain(state_dir=small_disk / "state")
    chain.execute("$.1")
    chain.close()
    fill(small_disk)
    done = run_coolmuscle("sim", "--tcp", "0", "--state", str(small_disk / "state"),
                          timeout=60, env=coolmuscle_env(COLUMNS="300"))
    assert done.returncode == 1, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "the disk is full" in lines[0], lines
    assert "Traceback" not in done.stderr

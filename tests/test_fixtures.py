"""The shared fixtures (tests/conftest.py, tests/fixtures.py) do what the suite relies on:
a served sim on free ports that answers on each of them and leaves no process behind,
a chain factory whose options reach the chain, a wait that gives up, a port that refuses.
"""

from __future__ import annotations

import os
import socket
import time
from pathlib import Path

import pytest
import serial
from pymodbus.client import ModbusTcpClient

from fixtures import (
    ChainFactory,
    ServedSim,
    SimFactory,
    closed_port,
    collect_events,
    free_port,
    wait_until,
)


def test_a_served_sim_answers_on_its_free_ports_and_is_gone_after_close(tmp_path: Path) -> None:
    sim = ServedSim(tmp_path / "sim.log", "--motors", "2", modbus_tcp=True, pty=True)
    try:
        assert sim.port != 5150 and sim.modbus_port != 1502
        with serial.serial_for_url(sim.url, timeout=5) as line:
            line.write(b"?96.2\r")
            assert line.read_until(b"Px.2=0\r\n").endswith(b"Px.2=0\r\n")
        with serial.Serial(sim.pty, timeout=5) as line:
            line.write(b"?96.1\r")
            assert line.read_until(b"Px.1=0\r\n").endswith(b"Px.1=0\r\n")
        client = ModbusTcpClient("127.0.0.1", port=sim.modbus_port, timeout=5)
        assert client.connect()
        client.close()
    finally:
        sim.close()
    assert sim.proc.returncode is not None
    with pytest.raises(ProcessLookupError):
        os.killpg(sim.pid, 0)                   # no process of its group is left


def test_a_pty_link_and_a_state_directory_are_in_the_banner(
        served_sim: SimFactory, tmp_path: Path) -> None:
    link, state = tmp_path / "cm-link", tmp_path / "state"
    sim = served_sim(tcp=False, pty=link, state=state)
    assert sim.pty == str(link) and link.is_symlink()
    assert sim.served == {"pty": f"{link} -> {os.readlink(link)}"}
    assert sim.stop() == 0 and not link.is_symlink()
    with pytest.raises(AssertionError, match="serves no tcp"):
        assert sim.port


def test_a_sim_that_cannot_start_says_why(tmp_path: Path) -> None:
    with pytest.raises(AssertionError, match=r"--tcp: bad TCP address"):
        ServedSim(tmp_path / "sim.log", "--tcp", "nope", tcp=False)


def test_make_chain_passes_its_options_and_runs_the_setup(
        make_chain: ChainFactory, tmp_path: Path) -> None:
    chain = make_chain(3, "rt3", state_dir=tmp_path, plant={"load_inertia": 1e-4},
                       setup=["K23.1=17", "P1.2=500"])
    assert sorted(chain.motors) == [1, 2, 3] and chain.firmware.name == "rt3"
    assert chain.store is not None and chain.motors[3].plant.load_inertia == 1e-4
    assert chain.execute("K23.1") == ["K23.1=17"] and chain.execute("P1.2") == ["P1.2=500"]
    statuses = collect_events(chain, ["status"])
    everything = collect_events(chain)
    chain.execute("?99.1")
    assert statuses == [] and [e.text for e in everything] == ["Ux.1=8"]


def test_wait_until_returns_what_it_saw() -> None:
    start = time.monotonic()
    assert not wait_until(lambda: False, timeout=0.2, step=0.05)
    assert 0.2 <= time.monotonic() - start < 2
    calls = iter([False, False, True])
    assert wait_until(lambda: next(calls), timeout=5, step=0.01)


def test_a_closed_port_refuses_and_a_free_port_can_be_bound() -> None:
    with closed_port() as port:
        with pytest.raises(ConnectionRefusedError):
            socket.create_connection(("127.0.0.1", port), timeout=5)
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", free_port()))

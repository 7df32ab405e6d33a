"""Transport registry, the Port entry point, the service life cycle and the stdio transport."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from coolmuscle.errors import TransportError
from coolmuscle.frontends import transports
from coolmuscle.frontends.transports.base import Port, split_after_line_ends
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.frontends.transports.stdio import StdioTransport
from coolmuscle.frontends.transports.tcp import TcpTransport
from fakes import FakeChain, fake_factory

SRC = str(Path(__file__).resolve().parents[1] / "src")


# -- registry -------------------------------------------------------------
def test_builtin_names_and_lazy_loading() -> None:
    assert {"tcp", "pty", "stdio"} <= set(transports.names())
    assert transports.load("tcp") is TcpTransport
    assert isinstance(transports.create("stdio", in_fd=0, out_fd=1), StdioTransport)


def test_registry_imports_nothing_until_a_transport_is_chosen() -> None:
    code = ("import sys, coolmuscle.frontends.transports as t; t.names(); "
            "print(any(m.startswith('coolmuscle.frontends.transports.') for m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": SRC}, timeout=30)
    assert out.stdout.strip() == "False", out.stderr


def test_unknown_name_lists_the_known_ones() -> None:
    with pytest.raises(TransportError,
                       match=r"unknown transport 'carrier-pigeon'; known: .*pty.*tcp"):
        transports.load("carrier-pigeon")


def test_a_broken_back_end_names_its_module_and_cause(tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "broken_transport_mod.py").write_text("import not_a_real_dependency_xyz\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setitem(transports.BUILTIN, "broken", "broken_transport_mod:Broken")
    with pytest.raises(TransportError) as info:
        transports.load("broken")
    message = str(info.value)
    assert "'broken'" in message and "broken_transport_mod" in message
    assert "not_a_real_dependency_xyz" in message and "unknown" not in message


def test_a_missing_attribute_is_reported(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(transports.BUILTIN, "nothing", "coolmuscle.frontends.transports.tcp:Nope")
    with pytest.raises(TransportError, match="has no attribute 'Nope'"):
        transports.load("nothing")


def test_entry_point_transports_are_known_but_builtins_win(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(transports, "_entry_points",
                        lambda: {"serial": "thirdparty.serialport:SerialTransport",
                                 "tcp": "evil:Tcp"})
    assert "serial" in transports.names()
    assert transports.registry()["tcp"] == transports.BUILTIN["tcp"]
    with pytest.raises(TransportError, match="cannot import module 'thirdparty.serialport'"):
        transports.load("serial")


# -- Port -----------------------------------------------------------------
def test_split_after_line_ends() -> None:
    assert split_after_line_ends(b"a\rb\r\nc") == [b"a\r", b"b\r", b"\n", b"c"]
    assert split_after_line_ends(b"") == []
    assert b"".join(split_after_line_ends(b"\r\r\nxx\n\n")) == b"\r\r\nxx\n\n"


def test_port_survives_a_failing_line_and_runs_the_lines_after_it() -> None:
    chain = FakeChain()
    port = Port(chain)
    out: list[bytes] = []
    port.add_listener(out.append)
    port.feed(b"boom\r?96.1\r")
    assert port.errors == 1
    assert b"".join(out) == b"boom\r\n?96.1\r\nPx.1=1\r\n"


ECHOED = (b"?96.1", b"P1.1=5", b"S.1=100", b"A.1=7", b"P2.1=-30")


@settings(max_examples=60, deadline=None)
@given(st.data())
def test_several_hosts_each_lines_echo_is_a_whole_line_however_the_bytes_come(
        data: st.DataObject) -> None:
    """Any interleaving: two or three hosts' lines in chunks of any
    size, taking turns in any order.  Every line of the shared output is one host's
    whole line (its echo) or a reply, each line sent is echoed once, and the echo comes
    before the reply to it (ch. 3 K23 8: the echo is part of the answer)."""
    chain = FakeChain()
    port = Port(chain)
    out: list[bytes] = []
    port.add_listener(out.append)
    hosts = data.draw(st.integers(2, 3))
    lanes = [port.open_lane(f"h{n}") for n in range(hosts)]
    sent = [data.draw(st.lists(st.sampled_from(ECHOED), min_size=1, max_size=4))
            for _ in range(hosts)]
    pending = []
    for lines in sent:
        stream = b"".join(line + b"\r" for line in lines)
        cuts = sorted(data.draw(st.sets(st.integers(1, len(stream) - 1), max_size=6)))
        pending.append([stream[a:b] for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True)])
    while any(pending):
        n = data.draw(st.sampled_from([i for i, chunks in enumerate(pending) if chunks]))
        lanes[n].feed(pending[n].pop(0))
    text = b"".join(out)
    assert text.endswith(b"\r\n")
    got = text.split(b"\r\n")[:-1]
    echoes = [line for line in got if not line.startswith(b"Px.1=")]
    assert sorted(echoes) == sorted(line for lines in sent for line in lines), text
    for i, line in enumerate(got):                  # each reply right after its query
        if line.startswith(b"Px.1="):
            assert got[i - 1] == b"?96.1", text


def test_port_discard_partial_forgets_a_half_line() -> None:
    chain = FakeChain()
    port = Port(chain)
    out: list[bytes] = []
    port.add_listener(out.append)
    port.feed(b"?9")
    assert port.discard_partial() is True
    port.feed(b"?96.1\r")
    assert b"".join(out) == b"?9?96.1\r\nPx.1=1\r\n"


# -- service --------------------------------------------------------------
def test_service_start_failure_cleans_up_and_closes_the_chain() -> None:
    chains: list[FakeChain] = []

    def make() -> FakeChain:
        chains.append(FakeChain())
        return chains[-1]

    with ServiceThread(fake_factory(), lambda: [TcpTransport(port=0)]) as first:
        busy = first.transports[0].info()["port"]
        with pytest.raises(TransportError, match="cannot listen"):
            ServiceThread(make, lambda: [TcpTransport(port=0), TcpTransport(port=busy)]).start()
    assert chains[0].closed


def test_service_call_runs_in_the_service_thread_at_wall_clock_time() -> None:
    with ServiceThread(fake_factory(), lambda: []) as st_:
        time.sleep(0.05)
        now = st_.call(lambda: st_.chain.kernel.now)
        assert now >= 40_000_000
    assert st_.chain.closed


# -- stdio ----------------------------------------------------------------
def test_stdio_transport_over_pipes_and_end_of_input_stops_the_service() -> None:
    host_to_motor_r, host_to_motor_w = os.pipe()
    motor_to_host_r, motor_to_host_w = os.pipe()
    st_ = ServiceThread(fake_factory(move_time=0.05),
                        lambda: [StdioTransport(host_to_motor_r, motor_to_host_w)]).start()
    try:
        os.write(host_to_motor_w, b"?96.1\r^.1\r")
        want = b"?96.1\r\nPx.1=1\r\n^.1\r\nUx.1=8\r\n"
        got = b""
        deadline = time.monotonic() + 5
        while got != want and time.monotonic() < deadline:
            got += os.read(motor_to_host_r, 4096)
        assert got == want
        os.close(host_to_motor_w)            # end of input
        assert st_._thread is not None
        st_._thread.join(5)
        assert not st_._thread.is_alive(), "service did not stop at end of input"
    finally:
        st_.stop()
        for fd in (host_to_motor_r, motor_to_host_r, motor_to_host_w):
            try:
                os.close(fd)
            except OSError:
                pass


def test_stdio_reads_a_regular_file(tmp_path: Path) -> None:
    script = tmp_path / "in.txt"
    script.write_bytes(b"?96.1\r")
    out = tmp_path / "out.txt"
    with open(script, "rb") as fin, open(out, "wb") as fout:
        st_ = ServiceThread(fake_factory(), lambda: [StdioTransport(fin.fileno(), fout.fileno())])
        st_.start()
        assert st_._thread is not None
        st_._thread.join(5)
        st_.stop()
    assert out.read_bytes() == b"?96.1\r\nPx.1=1\r\n"


def test_stdio_as_a_child_process_is_driven_by_pipes(tmp_path: Path) -> None:
    code = textwrap.dedent("""
        import asyncio, sys
        sys.path[:0] = [sys.argv[1], sys.argv[2]]
        from fakes import FakeChain
        from coolmuscle.frontends.transports.service import Service
        from coolmuscle.frontends.transports.stdio import StdioTransport
        async def main():
            service = Service(FakeChain(), [StdioTransport()])
            await service.start()
            await service.wait()
            await service.close()
        asyncio.run(main())
    """)
    out = subprocess.run([sys.executable, "-c", code, SRC, str(Path(__file__).parent)],
                         input=b"?96.1\r?96.1\r", capture_output=True, timeout=30)
    assert out.stdout == b"?96.1\r\nPx.1=1\r\n?96.1\r\nPx.1=2\r\n", out.stderr

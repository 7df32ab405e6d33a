"""The page's desk without a browser: its requests over the page's own WebSocket.

* the virtual page (``coolmuscle sim --web``): the K table (table 6.1 beside ``?90``), a K
  write read back on the motor's own TCP host line, out of range refused before sending
  with the catalogue's reason, the line's own K refused, ``$``, the buttons (jog,
  free, enable, alarm reset after an injected alarm), scan, backup and restore (and a
  backup of another firmware refused, nothing written);
* the page of a line (``coolmuscle web HOST:PORT``, :mod:`coolmuscle.tools.web.linepage`)
  over TCP to a served chain: "real", the poll's values, the console, the requests only
  a virtual motor takes refused with their reason;
* the poll's budget (:func:`coolmuscle.tools.web.line.poll_period`).
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterator
from typing import Any

import aiohttp
import pytest

from coolmuscle.chain import Chain
from coolmuscle.frontends.transports import create
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.tools.desk import backup, render_backup
from coolmuscle.tools.web.line import POLL_SHARE, LineDevice, open_line, poll_period, round_bytes
from coolmuscle.tools.web.linepage import LinePage
from coolmuscle.tools.web.server import WebTransport
from web_support import HostLine, ask, ws_frames


@pytest.fixture
def served() -> Iterator[ServiceThread]:
    st = ServiceThread(lambda: Chain(motors=2),
                       lambda: [create("tcp", port=0), WebTransport(port=0)]).start()
    yield st
    st.stop()


@pytest.fixture
def host(served: ServiceThread) -> Iterator[HostLine]:
    line = HostLine(served.transports[0].info()["port"])
    yield line
    line.close()


async def _session(url: str, requests: list[dict[str, Any]],
                   timeout: float = 20.0) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """The page's hello and the results of ``requests``, in order."""
    async with aiohttp.ClientSession() as session, session.ws_connect(url + "ws") as ws:
        hello = await ws_frames(ws, lambda f: f["t"] == "hello", timeout=10)
        results = [await ask(ws, request, rid, timeout)
                   for rid, request in enumerate(requests, start=1)]
        return hello, results


def test_virtual_page_k_editor_writes_reads_back_and_refuses_out_of_range(
        served: ServiceThread, host: HostLine) -> None:
    """ch. 3 K24 (10..50000, factory 1000); K20 changes the very line (ch. 3 K20)."""
    hello, (table, low, good, line_k, saved) = asyncio.run(_session(
        served.transports[1].url,
        [{"t": "k_table", "motor": 1}, {"t": "k_write", "motor": 1, "k": 24, "value": 5},
         {"t": "k_write", "motor": 1, "k": 24, "value": 2000},
         {"t": "k_write", "motor": 1, "k": 20, "value": 1}, {"t": "save", "motor": 2}]))
    assert hello["line"] == {"kind": "virtual", "text": "virtual"}
    rows = {row["k"]: row for row in table["rows"]}
    assert table["source"] == "table 6.1" and 21 not in rows          # reserved on CM2
    assert rows[24]["value"] == 1000 and rows[24]["default"] == 1000
    assert rows[24]["range"] == "10..50000" and not rows[24]["changed"]
    assert rows[85]["firmware"] == ["cm2", "rt3", "cm1"] and rows[20]["line"]
    assert low == {"t": "result", "id": 2, "ok": False,
                   "error": "K24=5 is out of range (10..50000)"}
    assert good["ok"] and (good["value"], good["changed"]) == (2000, True)
    assert host.query("K24.1", r"K24\.1=-?\d+") == "K24.1=2000"       # on the motor itself
    assert not line_k["ok"] and line_k["error"].startswith("K20 changes the baud rate")
    assert host.query("K20.1", r"K20\.1=-?\d+") == "K20.1=0"           # not sent
    assert saved["ok"] and saved["saved"]


def test_virtual_page_buttons_jog_free_enable_and_alarm_reset(
        served: ServiceThread, host: HostLine) -> None:
    """Jog: ``P.n+=d, ^.n`` (6.2 relative data); ``)`` frees (Ux 16); ``(`` enables and
    clears a latched alarm (docs/fidelity.md)."""
    start = int(host.query("?96.2", r"Px\.2=-?\d+").split("=")[1])
    served.call(lambda: served.chain.execute("S.2=100", motor=2))
    _, (jog,) = asyncio.run(_session(served.transports[1].url,
                                     [{"t": "motion", "motor": 2, "what": "jog+",
                                       "step": 500}]))
    assert jog["sent"] == "P.2+=500, ^.2"
    assert host.query("?96.2", r"Px\.2=-?\d+", timeout=10) and _settles(
        host, f"Px.2={start + 500}")
    served.call(served.chain.inject_fault, 2, "over_current")
    _, (alarmed, reset, free, enable, bad) = asyncio.run(_session(
        served.transports[1].url,
        [{"t": "cml", "line": "?99.2", "motor": 2},
         {"t": "motion", "motor": 2, "what": "alarm_reset"},
         {"t": "motion", "motor": 2, "what": "free"},
         {"t": "motion", "motor": 2, "what": "enable"},
         {"t": "motion", "motor": 2, "what": "spin"}]))
    assert alarmed["replies"] == ["Ux.2=64"]                      # 6.6 ?99: over current
    assert (reset["sent"], reset["status"], reset["text"]) == ("(.2", 8, "Ux=8 in position")
    assert (free["status"], enable["status"]) == (16, 8)
    assert not bad["ok"] and "unknown button 'spin'" in bad["error"]


def _settles(host: HostLine, wanted: str, seconds: float = 10.0) -> bool:
    import time
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if host.query("?96.2", r"Px\.2=-?\d+") == wanted:
            return True
        time.sleep(0.1)
    return False


def test_virtual_page_scan_backup_restore_and_another_firmware_refused(
        served: ServiceThread, host: HostLine) -> None:
    rt3 = render_backup(backup("coolmuscle://?firmware=rt3&mode=fast"))
    _, (scan, saved, restored, other) = asyncio.run(_session(
        served.transports[1].url,
        [{"t": "scan"}, {"t": "backup"}, {"t": "restore", "text": "", "save": False},
         {"t": "restore", "text": rt3, "name": "rt3.cml", "save": True}]))
    assert scan["lines"] == [f"ID{n}  K20=0 (38400 bit/s)  cm2  ID{n} : CM2v3.10R.1 #0802A12345"
                             for n in (1, 2)]
    assert saved["name"].endswith(".cml") and "# == ID2 : CM2v3.10R.1" in saved["text"]
    assert not restored["ok"] and "not a coolmuscle backup" in restored["error"]
    assert not other["ok"]
    assert other["error"] == (
        "rt3.cml holds ID1 of rt3 (ID1 : CM1v3.00R.1 #0000A00000), the virtual chain's ID1 "
        "is cm2 (ID1 : CM2v3.10R.1 #0802A12345): K85, K87 do not apply there; nothing "
        "written")
    # a backup restored after a change gives the change back, read back part by part
    served.call(lambda: served.chain.execute("K24.1=3000", motor=1))
    _, (again,) = asyncio.run(_session(served.transports[1].url, [
        {"t": "restore", "text": saved["text"], "save": False}]))
    assert again["restored"] and "ID1 K parameters: 1 line(s) written, read back equal" \
        in again["lines"]
    assert host.query("K24.1", r"K24\.1=-?\d+") == "K24.1=1000"


def test_page_of_a_line_over_tcp_says_real_polls_and_refuses_what_only_a_sim_has(
        served: ServiceThread, host: HostLine) -> None:
    port = served.transports[0].info()["port"]

    async def main() -> tuple[dict[str, Any], list[dict[str, Any]], dict[str, Any]]:
        opened, found = await asyncio.to_thread(open_line, f"127.0.0.1:{port}")
        line = LineDevice(opened, found)
        page = LinePage(line, port=0)
        await page.open()
        try:
            async with aiohttp.ClientSession() as session, \
                    session.ws_connect(page.url + "ws") as ws:
                hello = await ws_frames(ws, lambda f: f["t"] == "hello", timeout=10)
                snap = await ws_frames(ws, lambda f: f["t"] == "snap" and f["m"][0][1]
                                       is not None, timeout=10)
                results = [await ask(ws, request, rid, 20) for rid, request in enumerate([
                    {"t": "cml", "line": "?97.1", "motor": 1},
                    {"t": "input", "motor": 1, "n": 1, "on": True},
                    {"t": "fault", "motor": 1, "fault": "overload"},
                    {"t": "k_write", "motor": 2, "k": 24, "value": 2500},
                    {"t": "cml", "line": "?99.3", "motor": 3},
                    {"t": "wire_fault", "door": "host-line", "kind": "drop"}], start=1)]
                return hello, results, snap
        finally:
            await page.close()

    hello, (console, inputs, fault, k_write, no_motor, wire), snap = asyncio.run(main())
    line = hello["line"]
    assert line["kind"] == "real"
    assert line["text"] == f"2 real motors on socket://127.0.0.1:{port} (K20 38.4 kbps)"
    assert hello["motors"] == [1, 2] and hello["faults"] == {} and hello["wire"] is None
    fields = hello["fields"]
    row = dict(zip(fields, snap["m"][0], strict=True))
    assert (row["id"], row["position"], row["speed"], row["torque"]) == (1, 0, 0, 0)
    assert row["target"] is None and row["voltage"] is None          # not polled
    assert console["replies"] == ["Sx.1=0"]
    assert not inputs["ok"] and "wired" in inputs["error"]
    assert not fault["ok"] and "virtual motor only" in fault["error"]
    assert not wire["ok"] and "virtual motor's doors only" in wire["error"]
    assert k_write["ok"] and host.query("K24.2", r"K24\.2=-?\d+") == "K24.2=2500"
    assert not no_motor["ok"] and no_motor["error"].startswith("no motor ID3 on socket://")


@pytest.mark.parametrize("baud", [9600, 38400, 230400])
def test_the_poll_takes_at_most_a_quarter_of_the_line(baud: int) -> None:
    """A round: ``?96 ?97 ?98 ?99 ?71`` with their echoes and the longest replies
    (6.6); the rounds are spaced so they take at most POLL_SHARE of the line."""
    sent, received = round_bytes([1])
    assert (sent, received) == (30, 107)
    period = poll_period(baud, [1])
    assert received * 10 / baud / period <= POLL_SHARE + 1e-9
    assert period >= 0.05                         # 20 Hz at most
    assert poll_period(baud, [1, 2, 3]) >= 3 * received * 10 / baud / POLL_SHARE - 1e-9


def test_the_poll_plan_as_the_banner_and_the_docs_say_it() -> None:
    from coolmuscle.tools.web.line import PollPlan
    assert PollPlan(38400, (1,)).describe() == (
        "9.0 rounds a second (107 bytes from the motors a round at most: 28 ms of 38400 "
        "bit/s, 25% of the line)")
    assert PollPlan(9600, (1, 2, 3)).describe().startswith("0.7 rounds a second (321 bytes")

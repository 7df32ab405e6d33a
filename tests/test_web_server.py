"""The dashboard server over its own protocol (aiohttp WebSocket client), no browser.

What the page may do and what it may not: every request is checked against the motor's
own answers on its TCP host line (cml-users-guide.txt 6.6 queries), bad input gets a
clear message or the motor's own error, and access is guarded (token off loopback,
Host and Origin checks).
"""

from __future__ import annotations

import asyncio
import base64
import json
import logging
import multiprocessing
import os
import socket
import struct
import time

import aiohttp
import pytest

from coolmuscle.errors import TransportError
from coolmuscle.tools.web.access import Access, expand_web_flag, parse_web_address
from web_support import ROOT, HostLine, ask, count_snapshots, serve, ws_frames


@pytest.fixture(scope="module")
def served():
    st = serve(motors=2)
    yield st
    st.stop()


def _url(st) -> str:
    return st.transports[1].url


def _run(coro):
    return asyncio.run(coro)


async def _with_ws(url: str, body, **kw):
    async with aiohttp.ClientSession() as session:
        async with session.ws_connect(url + "ws", **kw) as ws:
            hello = await ws_frames(ws, lambda f: f["t"] == "hello")
            return await body(ws, hello)


def test_hello_describes_the_chain(served):
    async def body(ws, hello):
        return hello
    hello = _run(_with_ws(_url(served), body))
    assert hello["motors"] == [1, 2]
    assert hello["io"] == {"inputs": 6, "outputs": 4}
    assert set(hello["faults"]) >= {"overload", "encoder", "stuck_input", "broken_cable"}
    assert [row[0] for row in hello["snap"]["m"]] == [1, 2]


def test_6_6_query_from_the_page_answers_as_the_host_line(served):
    host = HostLine(served.transports[0].info()["port"])
    try:
        async def body(ws, hello):
            return await ask(ws, {"t": "cml", "line": "?96.2"})
        result = _run(_with_ws(_url(served), body))
        assert result["ok"] and result["replies"] == [host.query("?96.2", r"Px\.2=-?\d+")]
    finally:
        host.close()


def test_malformed_cml_gets_a_clear_note_and_the_motor_stays_silent_k23(served):
    async def body(ws, hello):
        return await ask(ws, {"t": "cml", "line": "P.1=((("})
    result = _run(_with_ws(_url(served), body))
    assert result["ok"] and result["replies"] == []
    assert "not CML" in result["note"] and "K23.1 lacks 16" in result["note"]


def test_out_of_range_with_k23_messages_gets_the_motors_error_line(served):
    """ch. 3 K23 function 16: error messages are printed; P out of range is error00/02."""
    host = HostLine(served.transports[0].info()["port"])
    try:
        host.query("K23.1=17", r"K23\.1=17")
        async def body(ws, hello):
            return await ask(ws, {"t": "cml", "line": "P.1=999999999"})
        result = _run(_with_ws(_url(served), body))
        assert result["ok"] and result["replies"] == [host.query("P.1=999999999",
                                                                  r"error\d\d\.1.*")]
        assert result["replies"][0].startswith("error00.1")
    finally:
        host.query("K23.1=1", r"K23\.1=1")
        host.close()


@pytest.mark.parametrize("request_, words", [
    ({"t": "analog", "counts": 2000}, "0..1023"),
    ({"t": "analog", "counts": 10, "motor": 9}, "no motor ID9"),
    ({"t": "input", "n": "x", "on": True}, "input"),
    ({"t": "fault", "fault": "gremlins"}, "unknown fault"),
    ({"t": "fault", "fault": "overload", "params": {"torque": "x" * 100}}, "parameters"),
    ({"t": "fault", "fault": "stuck_input", "params": {"input": 99}}, "1..6"),
    ({"t": "cml", "line": "P.1=1\rP.1=2"}, "one line"),
    ({"t": "cml", "line": "?" * 600}, "too long"),
    ({"t": "warp"}, "unknown request"),
    ({"t": []}, "unknown request"),          # unhashable kinds: an answer, not a 500
    ({"t": {"a": 1}}, "unknown request"),
    ({"t": None}, "unknown request"),
])
def test_bad_requests_get_a_clear_message(served, request_, words):
    async def body(ws, hello):
        return await ask(ws, request_)
    result = _run(_with_ws(_url(served), body))
    assert result["ok"] is False and words in result["error"]
    assert "Traceback" not in result["error"]


def test_malformed_json_and_nan_are_refused_and_the_socket_lives_on(served):
    async def body(ws, hello):
        await ws.send_str("{not json")
        first = await ws_frames(ws, lambda f: f["t"] == "result")
        await ws.send_str('{"t": "analog", "id": 3, "counts": NaN}')
        second = await ws_frames(ws, lambda f: f["t"] == "result")
        third = await ask(ws, {"t": "cml", "line": "?99.1"}, rid=4)
        return first, second, third
    first, second, third = _run(_with_ws(_url(served), body))
    assert not first["ok"] and "not a JSON request" in first["error"]
    assert not second["ok"]
    assert third["ok"] and third["replies"][0].startswith("Ux.1=")


def test_huge_websocket_message_closes_that_socket_1009_only(served):
    async def body(ws, hello):
        await ws.send_str(json.dumps({"t": "cml", "line": "x" * 400_000}))
        msg = await ws.receive(timeout=5)
        for _ in range(50):     # feed frames sent before the close arrive first under load
            if msg.type != aiohttp.WSMsgType.TEXT or json.loads(msg.data).get("t") == "result":
                break
            msg = await ws.receive(timeout=5)
        return msg.type, ws.close_code
    kind, code = _run(_with_ws(_url(served), body))
    assert kind in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.CLOSING)
    assert code == 1009

    async def again(ws, hello):
        return await ask(ws, {"t": "cml", "line": "?99.1"})
    assert _run(_with_ws(_url(served), again))["ok"]


def test_bank_with_checker_errors_is_not_sent_and_names_its_line(served):
    host = HostLine(served.transports[0].info()["port"])
    try:
        async def body(ws, hello):
            return await ask(ws, {"t": "bank_upload", "motor": 2,
                                  "text": "B3.2\nS.2=100\nP.2=(((\nEND"})
        result = _run(_with_ws(_url(served), body))
        assert result["ok"] and result["uploaded"] is False
        errors = [d for d in result["diagnostics"] if d["severity"] == "error"]
        assert errors and errors[0]["line"] == 3
        host.query("K23.2=17", r"K23\.2=17")
        assert host.query("?3.2", r"error\d\d\.2.*").startswith("error")   # 6.6: no bank 3
    finally:
        host.query("K23.2=1", r"K23\.2=1")
        host.close()


def test_bank_lines_without_an_id_go_to_the_pages_motor_and_into_the_log():
    """2.2.2: ``B3`` typed for motor 2 is bank 3 of ID2; every line the upload sends
    (the bank, its read-back ``?3.2``) shows in the page's log as sent (``>``)."""
    st = serve(motors=2)
    host = HostLine(st.transports[0].info()["port"])
    try:
        async def body(ws, hello):
            result = await ask(ws, {"t": "bank_upload", "motor": 2, "text": "B3\nS1\nEND"})
            sent = []
            while "?3.2" not in sent:
                frame = await ws_frames(ws, lambda f: f["t"] == "log")
                sent += [line[2] for line in frame["lines"] if line[1] == ">"]
            return result, sent
        result, sent = _run(_with_ws(_url(st), body))
        assert result["ok"] and result["uploaded"] is True
        assert (result["banks"], result["differences"]) == (["B3.2"], [])
        assert [line for line in sent if not line.startswith("?96")] == ["B3", "S1", "END",
                                                                         "?3.2"]
        assert host.query("?3.2", r"S1.*") == "S1.2"
    finally:
        host.close()
        st.stop()


def test_the_upload_is_the_clients_reporting_motor_errors_and_read_back_differences():
    """The page's upload is :func:`coolmuscle.client.banks.upload` on the device: with
    K23 16 the motor's own ``error02`` (no room left, 2.2.2) is reported on the file
    line that met it, and the read-back (6.6 ``?3.2``) names the lines that are missing."""
    from coolmuscle.chain import Chain
    from coolmuscle.tools.web.banks import upload_banks

    chain = Chain(motors=2)
    filled = upload_banks(chain, 2, "B2.2\n" + "T1.2\n" * 495 + "END", lambda _n: None)
    assert filled["uploaded"] and filled["differences"] == []
    text = "B3.2\n" + "T2.2\n" * 8 + "END"
    missing = [f"B3.2 line {n} (file line {n + 1}): missing on the motor: 'T2.2'"
               for n in (6, 7, 8)]
    silent = upload_banks(chain, 2, text, lambda _n: None)
    assert silent["uploaded"] and silent["differences"] == missing
    chain.execute("K23.2=17")
    told = upload_banks(chain, 2, text, lambda _n: None)
    assert told["differences"] == ["line 7: error02.2: too many steps!!", *missing]


def _raw_websocket(port: int) -> socket.socket:
    """A WebSocket opened by hand (RFC 6455 handshake), to send what no library would."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=5)
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall((f"GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
                  f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                  "Sec-WebSocket-Version: 13\r\n\r\n").encode())
    head = b""
    while b"\r\n\r\n" not in head:
        head += sock.recv(4096)
    assert head.startswith(b"HTTP/1.1 101"), head[:80]
    return sock


def test_page_closed_mid_upload_leaves_the_banks_and_the_server_alone(served):
    """A request cut off in the middle (the first fragment of a WebSocket message, then
    the connection drops: RFC 6455 5.4) is never applied; the server and the other
    pages go on."""
    url, port = _url(served), served.transports[1].info()["port"]

    async def watch_while_cut_off():
        async with aiohttp.ClientSession() as session:
            async with session.ws_connect(url + "ws") as other:
                await ws_frames(other, lambda f: f["t"] == "hello")
                sock = _raw_websocket(port)
                text = json.dumps({"t": "bank_upload", "id": 1,
                                   "text": "B7.1\nT1.1\nEND"}).encode()
                mask = os.urandom(4)
                piece = bytes(b ^ mask[i % 4] for i, b in enumerate(text[:20]))
                sock.sendall(bytes([0x01, 0x80 | 20]) + mask + piece)   # TEXT, FIN clear
                await asyncio.sleep(0.2)
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
                sock.close()                                           # the tab is gone
                return await ask(other, {"t": "banks", "motor": 1}, rid=9)
    listing = _run(watch_while_cut_off())
    assert listing["ok"]
    assert "B7.1" not in [b["label"] for b in listing["banks"]["banks"]]


def test_token_required_off_loopback_and_checked():
    access = Access("0.0.0.0", token="s3cret")
    assert access.token_required and access.token_ok("s3cret")
    assert not access.token_ok("nope") and not access.token_ok(None)
    assert not Access("127.0.0.1").token_required and Access("127.0.0.1").token_ok(None)
    assert Access("192.168.1.5").token          # a fresh random token when none is given


def test_non_loopback_bind_refuses_websocket_without_token():
    from coolmuscle.chain import Chain
    from coolmuscle.frontends.transports.service import ServiceThread
    from coolmuscle.tools.web.server import WebTransport
    with ServiceThread(lambda: Chain(), lambda: [WebTransport("0.0.0.0", 0)]) as st:
        web = st.transports[0]
        token, port = web.access.token, web.info()["port"]
        assert token and token in web.describe()

        async def probe():
            async with aiohttp.ClientSession() as session:
                base = f"http://127.0.0.1:{port}"
                async with session.get(base + "/") as page:
                    page_status = page.status
                async with session.get(base + "/api/info") as info:
                    needs = (await info.json())["token_required"]
                with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
                    await session.ws_connect(base + "/ws")
                async with session.get(base + "/api/trace.csv") as trace:
                    trace_status = trace.status
                async with session.ws_connect(base + "/ws?token=" + token) as ws:
                    hello = await ws_frames(ws, lambda f: f["t"] == "hello")
                return page_status, needs, refused.value.status, trace_status, hello
        page_status, needs, ws_status, trace_status, hello = _run(probe())
        assert (page_status, needs, ws_status, trace_status) == (200, True, 401, 401)
        assert hello["motors"] == [1]


def test_loopback_refuses_foreign_origin_and_host(served):
    url = _url(served)

    async def probe():
        async with aiohttp.ClientSession() as session:
            with pytest.raises(aiohttp.WSServerHandshakeError) as foreign:
                await session.ws_connect(url + "ws", headers={"Origin": "http://evil.example"})
            async with session.get(url, headers={"Host": "evil.example:8080"}) as rebound:
                rebound_status = rebound.status
            return foreign.value.status, rebound_status
    assert _run(probe()) == (403, 421)


def test_trace_and_plot_download_after_record():
    st = serve(motors=1)
    url = st.transports[1].url

    async def fetch():
        async with aiohttp.ClientSession() as session:
            async with session.get(url + "api/trace.csv") as r:
                before = (r.status, (await r.json())["error"])
            async with session.ws_connect(url + "ws") as ws:
                await ws_frames(ws, lambda f: f["t"] == "hello")
                recording = await ask(ws, {"t": "record"})
                await ask(ws, {"t": "cml", "line": "S.1=100, A.1=100, P.1=500, ^.1"}, rid=2)
                await asyncio.sleep(0.5)
            async with session.get(url + "api/trace.csv") as r:
                csv = (r.status, await r.text())
            async with session.get(url + "api/plot.png") as r:
                png = (r.status, await r.read())
            return before, recording, csv, png
    try:
        before, recording, (csv_status, csv), (png_status, png) = _run(fetch())
    finally:
        st.stop()
    assert before[0] == 409 and "Record" in before[1]
    assert recording["ok"] and recording["recording"]
    assert csv_status == 200 and csv.startswith("time_s,m1.")
    positions = [float(row.split(",")[3]) for row in csv.splitlines()[1:]]
    assert max(positions) > 0                   # the move is in the trace
    assert png_status == 200 and png[:8] == b"\x89PNG\r\n\x1a\n"


def test_web_address_forms():
    assert parse_web_address(None) == ("127.0.0.1", 8080)
    assert parse_web_address("9000") == ("127.0.0.1", 9000)
    assert parse_web_address("0.0.0.0:8080") == ("0.0.0.0", 8080)
    assert parse_web_address("[::1]:81") == ("::1", 81)
    assert parse_web_address("0.0.0.0") == ("0.0.0.0", 8080)
    with pytest.raises(TransportError, match="HOST:"):
        parse_web_address("http://x")
    assert expand_web_flag(["sim", "--web"]) == ["sim", "--web", "127.0.0.1:8080"]
    assert expand_web_flag(["run", "a.cml", "--web", "--motors", "2"])[3] == "127.0.0.1:8080"
    assert expand_web_flag(["sim", "--web", "9000"]) == ["sim", "--web", "9000"]
    assert expand_web_flag(["sim", "--web", "bad:x"]) == ["sim", "--web", "bad:x"]
    script = str(ROOT / "examples" / "2.1-operation.cml")
    assert expand_web_flag(["run", "--web", script]) == ["run", "--web", "127.0.0.1:8080",
                                                         script]


def test_twenty_clients_on_fifteen_motors_keep_20_updates_a_second():
    """Load: 20 WebSocket clients (in another process, as browsers are) watch a 15-motor
    chain while every motor moves; each gets at least 20 snapshots a second."""
    st = serve(motors=15)
    try:
        url = st.transports[1].url
        host = HostLine(st.transports[0].info()["port"])
        moves = ", ".join(f"S.{m}=20, A.{m}=100, P.{m}=50000" for m in range(1, 16))
        host.sock.sendall(moves.encode() + b"\r" + ", ".join(
            f"^.{m}" for m in range(1, 16)).encode() + b"\r")
        spawn = multiprocessing.get_context("spawn")
        queue = spawn.Queue()
        child = spawn.Process(target=count_snapshots, args=(url, 20, 2.0, queue))
        child.start()
        results = queue.get(timeout=60)
        child.join(10)
        host.close()
    finally:
        st.stop()
    assert [motors for _, motors in results] == [15] * 20
    counts = [count for count, _ in results]
    print("snapshots in 2 s per client:", counts)
    assert min(counts) / 2.0 >= 20, counts


def test_trace_download_writes_what_run_trace_writes(tmp_path):
    """The page's CSV is the recorder's own CSV (docs/plots.md), sampled in chunks."""
    from coolmuscle.chain import Chain
    from coolmuscle.sim.kernel import seconds
    from coolmuscle.tools.trace.recorder import record
    from coolmuscle.tools.web import traces

    chain = Chain(motors=2)
    recorder = record(chain)
    chain.execute("S.1=100, A.1=100, P.1=3000, ^.1, S.2=50, A.2=50, P.2=-800, ^.2")
    chain.kernel.run(until=seconds(2))
    header, rows = traces.trace_rows(recorder, 0.001, chain.kernel.now)
    traces.write_rows(tmp_path / "page.csv", header, list(rows))
    recorder.write_csv(tmp_path / "run.csv", 0.001)
    assert (tmp_path / "page.csv").read_text() == (tmp_path / "run.csv").read_text()


def test_no_polling_storm_while_nothing_moves(served):
    """Idle motors: no snapshot is sent while no value changes, only the 1 s tick."""
    async def body(ws, hello):
        await asyncio.sleep(1.5)              # the fast second after connecting passes
        frames = []
        end = time.monotonic() + 2.0
        while time.monotonic() < end:
            try:
                frames.append(await ws_frames(ws, lambda f: True,
                                              timeout=max(0.05, end - time.monotonic())))
            except TimeoutError:
                break
        return frames
    frames = _run(_with_ws(_url(served), body))    # 3.5 s since the hello in all
    kinds = [f["t"] for f in frames]
    assert "snap" not in kinds and kinds.count("tick") <= 5 and len(kinds) <= 5, kinds


def test_odd_origin_and_token_are_refused_not_raised():
    """An Origin urlsplit cannot parse ("http://[::1") and a token of undecodable bytes
    (header bytes FF FE arrive as surrogates) are refusals, never exceptions (an attack
    found a 500 and a traceback for each)."""
    access = Access("0.0.0.0", token="s3cret")
    assert not access.origin_ok("http://[::1", "127.0.0.1:8080")
    assert not access.token_ok("\udcff\udcfe") and not access.token_ok("s3cret\udcff")
    assert access.token_ok("s3cret")


def _raw(port: int, data: bytes, wait: float = 2.0) -> bytes:
    with socket.create_connection(("127.0.0.1", port), timeout=wait) as sock:
        sock.sendall(data)
        out = b""
        try:
            while True:
                chunk = sock.recv(65536)
                if not chunk:
                    break
                out += chunk
        except TimeoutError:
            pass
        return out


BAD_REQUESTS = [b"GET / HTTP/9.9\r\nHost: 127.0.0.1\r\n\r\n",
                b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: -1\r\n\r\n",
                b"GET /\x00 HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n",
                b"POST / HTTP/1.1\r\nHost: 127.0.0.1\r\nTransfer-Encoding: chunked\r\n\r\nzz\r\n",
                b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nX: " + b"a" * 20000 + b"\r\n\r\n"]


def test_malformed_http_gets_400_and_one_log_line_without_traceback(served, caplog):
    """Malformed requests: the client gets 400; the server logs one INFO line each, no
    traceback (an attack counted 100 tracebacks for 100 requests); a WebSocket upgrade
    with an unparsable Origin gets 403."""
    port = served.transports[1].info()["port"]
    caplog.set_level("INFO")
    for request in BAD_REQUESTS:
        assert _raw(port, request).split(b" ")[1] == b"400", request[:40]
    upgrade = (b"GET /ws HTTP/1.1\r\nHost: 127.0.0.1:%d\r\nOrigin: http://[::1\r\n"
               b"Upgrade: websocket\r\nConnection: Upgrade\r\n"
               b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
               % port)
    assert _raw(port, upgrade).startswith(b"HTTP/1.1 403")
    time.sleep(0.2)
    web = [r for r in caplog.records if r.name.startswith("coolmuscle.web")]
    assert not any(r.exc_info for r in caplog.records)
    assert not [r for r in web if r.levelno >= 40], [r.getMessage() for r in web]
    assert sum("Error handling request" in r.getMessage() for r in web) >= len(BAD_REQUESTS)


def test_a_connection_flood_is_capped_and_trickled_headers_time_out(monkeypatch):
    """At most MAX_CONNECTIONS connections at once (more are closed as they come: a
    flood once used up the file descriptors the motor's TCP and Modbus ports share); a
    connection whose request never completes is closed after IDLE_TIMEOUT."""
    from coolmuscle.tools.web import server as web_server
    monkeypatch.setattr(web_server, "MAX_CONNECTIONS", 20)
    monkeypatch.setattr(web_server, "IDLE_TIMEOUT", 0.5)
    st = serve()
    try:
        web = st.transports[1]
        port = web.info()["port"]
        held = []
        for _ in range(60):
            sock = socket.create_connection(("127.0.0.1", port), timeout=5)
            sock.sendall(b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n")     # never finished
            held.append(sock)
        time.sleep(0.2)
        assert len(st.call(lambda: web._runner.server.connections)) <= 20
        host = HostLine(st.transports[0].info()["port"])           # the motor still answers
        assert host.query("?96.1", r"Px\.1=-?\d+") == "Px.1=0"
        host.close()
        deadline = time.monotonic() + 5
        for sock in held:                            # all closed by the server (FIN or RST)
            sock.settimeout(max(0.1, deadline - time.monotonic()))
            try:
                assert sock.recv(100) == b""
            except ConnectionResetError:
                pass
            sock.close()
        assert _raw(port, b"GET /api/info HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                          b"Connection: close\r\n\r\n").startswith(b"HTTP/1.1 200")
    finally:
        st.stop()


def test_a_page_greeted_while_a_log_batch_waits_gets_each_line_once() -> None:
    """The hello's history holds the queued lines: the batch's flush does not send them
    again to that page (found as "trace recording started" twice on run --web)."""
    import asyncio

    from coolmuscle.tools.web.hub import Client, Hub

    async def body() -> tuple[list[str], list[str]]:
        hub = Hub(device=None, call=lambda fn, *a: fn(*a))
        hub._loop = asyncio.get_running_loop()
        old_page, new_page = Client(lambda _f: None), Client(lambda _f: None)
        hub.clients.add(old_page)
        hub.add_log([0, "note", "trace recording started", 0, "web"])
        greeted = {id(e) for e in hub.history}
        assert hub.pending() == greeted
        hub.clients.add(new_page)
        new_page.seen = hub.pending()
        hub.add_log([1, "reply", "Ux.1=8", 1, "motor"])
        hub._flush()
        texts = [[line[2] for line in json.loads(frame)["lines"]] for frame, _ in
                 (list(old_page.logs) + list(new_page.logs))]
        return texts[0], texts[1]
    old_lines, new_lines = asyncio.run(body())
    assert old_lines == ["trace recording started", "Ux.1=8"]
    assert new_lines == ["Ux.1=8"]


def test_the_page_beyond_max_pages_is_refused_and_api_info_says_why(monkeypatch):
    """docs/web.md Robustness: the 101st page's WebSocket gets 503; /api/info tells the
    page how many are open, so it can say so instead of only "reconnecting"."""
    from coolmuscle.tools.web import server as web_server
    monkeypatch.setattr(web_server, "MAX_PAGES", 2)
    st = serve()
    try:
        url = st.transports[1].url

        async def probe():
            async with aiohttp.ClientSession() as session:
                first = await session.ws_connect(url + "ws")
                second = await session.ws_connect(url + "ws")
                with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
                    await session.ws_connect(url + "ws")
                async with session.get(url + "api/info") as reply:
                    info = await reply.json()
                await first.close()
                await second.close()
                return refused.value.status, info
        status, info = _run(probe())
        assert status == 503 and (info["pages"], info["max_pages"]) == (2, 2)
    finally:
        st.stop()


def test_the_plot_import_beside_the_loop_is_waited_for_at_exit(monkeypatch) -> None:
    """``run --web`` imports matplotlib in a thread as the recording starts.  A daemon
    thread stopped at exit inside matplotlib's C++ extensions (Ctrl-C right after the
    start) aborted the process with SIGABRT ("terminate called without an active
    exception", seen in CI); the thread is not a daemon, so the exit waits for it."""
    import threading

    import coolmuscle.tools.web.traces as web
    from coolmuscle.chain import Chain

    started: list[threading.Thread] = []

    class Recorded(threading.Thread):
        def start(self) -> None:
            started.append(self)
            super().start()

    monkeypatch.setattr(web.threading, "Thread", Recorded)
    chain = Chain()
    try:
        assert web.start_recording(chain) is not None
    finally:
        chain.close()
    assert [t.name for t in started] == ["coolmuscle-web-plot-import"]
    assert not started[0].daemon
    started[0].join(30)


@pytest.mark.parametrize("params, name", [
    ({"motor": 2}, "overload"), ({"fault": "encoder"}, "overload"),
    ({"self": 1}, "overload"), ({"Torque": 5}, "overload"), ({"torque value": 5}, "overload"),
    ({}, ["overload"]), ({}, {"name": "overload"}), ({}, 7), ({}, None),
])
def test_fault_requests_with_odd_names_are_bad_requests_without_a_traceback(
        served, caplog, params, name):
    """Parameters named as ``inject_fault``'s own arguments (``motor``, ``fault``,
    ``self``) or a fault name that is not text: a clear refusal, no "internal error"
    and no traceback in the log (an attack found 362 KB of log for 500 such requests)."""
    async def body(ws, hello):
        return await ask(ws, {"t": "fault", "motor": 1, "fault": name, "params": params})
    with caplog.at_level(logging.DEBUG):
        result = _run(_with_ws(_url(served), body))
    assert result["ok"] is False and "internal error" not in result["error"]
    assert ("unknown fault" in result["error"] if not isinstance(name, str)
            else "takes no parameter" in result["error"]), result
    assert not [r for r in caplog.records if r.exc_info], "a traceback was logged"


@pytest.mark.parametrize("headers", [
    {"Origin": "http://evil.example"},
    {"Sec-Fetch-Site": "cross-site"},
    {"Sec-Fetch-Site": "same-site"},          # another port of the host: another site
    {"Sec-Fetch-Site": "cross-site", "Sec-Fetch-Dest": "image", "Sec-Fetch-Mode": "no-cors"},
])
@pytest.mark.parametrize("path", ["api/plot.png", "api/trace.csv", "api/trace.parquet"])
def test_downloads_asked_by_another_site_are_refused(path, headers):
    """A cross-site ``<img src=".../api/plot.png">`` made the simulator draw a plot per
    request in its loop (49 x 200 back to back, the host line's p99 at 1 s): a download
    request from another site (``Origin``, ``Sec-Fetch-Site``) is refused with 403 before
    anything is prepared; the page's own (``same-origin``), a typed-in address
    (``none``) and a script (neither header) are served."""
    st = serve(motors=1)
    url = st.transports[1].url
    web = st.transports[1]
    st.call(web.start_recording)

    async def fetch(extra):
        async with aiohttp.ClientSession() as session:
            async with session.get(url + path, headers=extra) as r:
                return r.status
    try:
        assert _run(fetch(headers)) == 403
        assert web.cross_site_refused == 1
        own = {"Origin": url.rstrip("/"), "Sec-Fetch-Site": "same-origin"}
        for allowed in (own, {"Sec-Fetch-Site": "none"}, {}):
            assert _run(fetch(allowed)) in (200, 409), allowed    # 409: no pyarrow
        assert web.cross_site_refused == 1
    finally:
        st.stop()


def test_run_web_stops_at_its_signal_while_the_script_plays() -> None:
    """``coolmuscle run FILE --web`` (docs/web.md "coolmuscle run script.cml --web"): a
    stop signal while the script plays (here in its ``@wait 30``) ends the run within
    a second or two, not when the script's waits are over."""
    from coolmuscle.chain import Chain
    from coolmuscle.tools.script.runner import TranscriptEntry, parse_script
    from coolmuscle.tools.web.run import _serve_run, web_transport
    from fixtures import wait_until_async

    shown: list[TranscriptEntry] = []

    async def body() -> float:
        chain = Chain()
        try:
            web = web_transport("127.0.0.1:0")
            stop = asyncio.Event()
            script = parse_script("?96.1\n@wait 30\n?96.1\n")
            run = asyncio.create_task(_serve_run(script, chain, web, None, shown.append,
                                                 lambda _text: None, stop))
            assert await wait_until_async(lambda: web.bound is not None or run.done())
            async with aiohttp.ClientSession() as session:
                async with session.ws_connect(web.url + "ws"):
                    assert await wait_until_async(lambda: any(e.direction == "<"
                                                              for e in shown))
                    stop.set()                   # the handler of run_served's signals
                    started = time.monotonic()
                    async with asyncio.timeout(5):
                        await run
                    return time.monotonic() - started
        finally:
            chain.close()
    assert _run(body()) < 3.0


def test_closing_ends_with_a_page_that_does_not_read() -> None:
    """The simulator stops (Ctrl-C, docs/reliability.md "Signals") while a page has
    stopped reading (a frozen tab, a laptop asleep on the LAN): its socket takes no
    more bytes and asyncio paused writing to it, as it does when a transport's buffer
    passes its high-water mark (forced here on the page's connection).  Closing the
    dashboard drops that page within its close timeout; it waited for the page to read
    again (the close frame's drain), so the simulator never stopped."""
    from coolmuscle.chain import Chain
    from coolmuscle.frontends.transports.service import Service
    from coolmuscle.tools.web.server import CLOSE_TIMEOUT, WebTransport
    from fixtures import wait_until_async

    async def body() -> tuple[float, bool]:
        chain = Chain()
        web = WebTransport(port=0)
        service = Service(chain, [web])
        await service.start()
        try:
            async with aiohttp.ClientSession() as session:
                async with session.ws_connect(web.url + "ws") as page:
                    await ws_frames(page, lambda f: f["t"] == "hello")
                    assert await wait_until_async(lambda: web.hub is not None
                                                  and len(web.hub.clients) == 1)
                    assert web._runner is not None
                    (connection,) = web._runner.server.connections   # the page's
                    connection.pause_writing()
                    started = time.monotonic()
                    async with asyncio.timeout(5 * CLOSE_TIMEOUT):
                        await service.close()
                    return time.monotonic() - started, connection.transport is None \
                        or connection.transport.is_closing()
        finally:
            chain.close()
    took, dropped = _run(body())
    assert took < 3 * CLOSE_TIMEOUT and dropped

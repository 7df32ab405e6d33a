"""The pages' requests share the loop with the host line (docs/web.md "Fair share").

A page's requests wait in a bounded queue (one beyond it is refused with a message),
run in turns with the other pages' at most 32 a wake-up (as Modbus TCP's requests),
and what a page queued is dropped when it leaves.  A bank text is checked and a plot
drawn in a worker thread; the model is only called in the loop's thread, and an
upload is sent in slices.  Counts, not times (the times are bench_reliability.py's
"web flood" row).  A slow bank check is simulated by holding the worker thread, so
a page is busy for as long as the test wants.
"""

from __future__ import annotations

import asyncio
import json
import threading
from collections.abc import Callable, Iterator
from typing import Any

import aiohttp
import pytest

import coolmuscle.tools.trace.plot as trace_plot
import coolmuscle.tools.web.actions as actions_module
import coolmuscle.tools.web.banks as banks_module
from coolmuscle.frontends.transports.service import ServiceThread
from coolmuscle.tools.web.turns import MAX_PER_WAKE, MAX_QUEUED
from fixtures import wait_until
from web_support import ask, serve, ws_frames


@pytest.fixture
def served() -> Iterator[ServiceThread]:
    st = serve(motors=2)
    yield st
    st.stop()


@pytest.fixture
def held_check(monkeypatch: pytest.MonkeyPatch) -> Iterator[threading.Event]:
    """Bank checks wait for the event (in their worker thread) before they check."""
    release = threading.Event()
    real = actions_module.check_program_text

    def slow(*args: Any) -> Any:
        release.wait(30)
        return real(*args)
    monkeypatch.setattr(actions_module, "check_program_text", slow)
    yield release
    release.set()


def run(coro: Any) -> Any:
    return asyncio.run(coro)


async def page(url: str, body: Callable[[Any], Any]) -> Any:
    async with aiohttp.ClientSession() as session:
        async with session.ws_connect(url + "ws") as ws:
            await ws_frames(ws, lambda f: f["t"] == "hello")
            return await body(ws)


async def results(ws: Any, count: int, timeout: float = 20.0) -> dict[int, dict[str, Any]]:
    """The next ``count`` results, by id."""
    got: dict[int, dict[str, Any]] = {}
    while len(got) < count:
        frame = await ws_frames(ws, lambda f: f.get("t") == "result", timeout)
        got[frame["id"]] = frame
    return got


def write_p(n: int) -> str:
    return json.dumps({"t": "cml", "id": n, "line": f"P{n}.1={n}", "motor": 1})


UPLOAD = json.dumps({"t": "bank_upload", "id": 0, "motor": 1, "text": "B9.1\nT1.1\nEND"})


async def started_upload(ws: Any, turns: Any) -> None:
    """Send the upload and wait until its turn came (the page is busy with it)."""
    await ws.send_str(UPLOAD)
    for _ in range(500):
        if turns.ran:
            return
        await asyncio.sleep(0.01)
    raise AssertionError("the upload did not start")


def registers(st: ServiceThread, numbers: range) -> list[int]:
    return st.call(lambda: [st.chain.get_register(1, "P", n) for n in numbers])


def test_a_pages_queue_is_bounded_and_one_beyond_is_refused(
        served: ServiceThread, held_check: threading.Event) -> None:
    """The page is busy (its bank upload is being checked) while it pipelines 200 more
    requests: 64 wait, the other 136 are answered at once ``busy`` and never run; once
    the upload ends the 64 run, in order, after it."""
    turns = served.transports[1].turns

    async def body(ws: Any) -> tuple[dict[int, dict[str, Any]], dict[int, dict[str, Any]]]:
        await started_upload(ws, turns)
        for n in range(1, 201):
            await ws.send_str(write_p(n))
        refused = await results(ws, 200 - MAX_QUEUED)
        held_check.set()
        return refused, await results(ws, MAX_QUEUED + 1)
    refused, answered = run(page(served.transports[1].url, body))
    assert sorted(refused) == list(range(MAX_QUEUED + 1, 201))
    assert all(not r["ok"] and r["error"].startswith("busy: 64 requests of this page")
               for r in refused.values())
    assert list(answered) == list(range(MAX_QUEUED + 1))          # in the page's order
    assert answered[0]["uploaded"] and all(r["ok"] for r in answered.values())
    assert registers(served, range(1, 201)) == list(range(1, MAX_QUEUED + 1)) + [0] * 136
    assert turns.refused == 136 and turns.most_per_wake <= MAX_PER_WAKE


def test_what_a_page_queued_is_dropped_when_it_leaves(
        served: ServiceThread, held_check: threading.Event) -> None:
    """A page queues 50 requests behind its upload and leaves: the 50 never run (the
    upload, begun, runs to its end: the bank is whole)."""
    turns = served.transports[1].turns

    async def body(ws: Any) -> None:
        await started_upload(ws, turns)
        for n in range(1, 51):
            await ws.send_str(write_p(n))
        await asyncio.sleep(0.3)
    run(page(served.transports[1].url, body))
    assert wait_until(lambda: turns.dropped == 50, 10, 0.01), turns.dropped
    held_check.set()
    assert wait_until(lambda: "T1.1" in served.call(served.chain.execute, "?9.1"), 10, 0.05)
    assert registers(served, range(1, 51)) == [0] * 50
    assert turns.ran == 1


def test_the_pages_take_turns_at_most_32_requests_a_wake_up(served: ServiceThread) -> None:
    """Three pages pipelining 60 requests each: all answered, never more than 32 run
    in one wake-up of the loop."""
    turns = served.transports[1].turns

    async def one(ws: Any, base: int) -> dict[int, dict[str, Any]]:
        for n in range(base, base + 60):
            await ws.send_str(write_p(n))
        return await results(ws, 60)

    async def three() -> list[dict[int, dict[str, Any]]]:
        url = served.transports[1].url
        return list(await asyncio.gather(*(page(url, lambda ws, b=b: one(ws, b))
                                           for b in (1, 61, 121))))
    answers = run(three())
    assert all(r["ok"] for got in answers for r in got.values())
    assert turns.ran == 180 and turns.refused == 0
    assert turns.most_per_wake <= MAX_PER_WAKE
    assert turns.wakeups >= 180 // MAX_PER_WAKE
    assert registers(served, range(1, 181)) == list(range(1, 181))


def test_bank_checks_and_plots_run_in_a_worker_the_model_in_the_loop(
        served: ServiceThread, monkeypatch: pytest.MonkeyPatch) -> None:
    """The pure work (checking a bank text, drawing a plot) runs in a worker thread;
    every model call (sending the bank's lines a slice at a time, sampling the trace)
    in the loop's thread; a 450-line bank goes in more than ten slices."""
    threads: dict[str, set[str]] = {}

    def spy(module: Any, name: str) -> None:
        real = getattr(module, name)

        def wrapper(*args: Any, **kw: Any) -> Any:
            threads.setdefault(name, set()).add(threading.current_thread().name)
            return real(*args, **kw)
        monkeypatch.setattr(module, name, wrapper)
    spy(actions_module, "check_program_text")
    spy(actions_module, "send_slice")
    spy(trace_plot, "draw_plot")
    spy(trace_plot, "sample_motors")
    web = served.transports[1]
    served.call(web.start_recording)
    text = "\n".join(["B2.1", *(f"T{n % 8 + 1}.1" for n in range(450)), "END"])

    async def body(ws: Any) -> dict[str, Any]:
        upload = await ask(ws, {"t": "bank_upload", "motor": 1, "text": text}, timeout=60)
        await ask(ws, {"t": "cml", "line": "S.1=100, A.1=100, P.1=500, ^.1"}, rid=2)
        await asyncio.sleep(0.3)
        async with aiohttp.ClientSession() as session:
            async with session.get(web.url + "api/plot.png") as r:
                assert r.status == 200 and (await r.read())[:4] == b"\x89PNG"
        return upload
    upload = run(page(web.url, body))
    assert upload["ok"] and upload["uploaded"] and upload["differences"] == []
    loop_thread = {"coolmuscle-service"}
    assert threads["send_slice"] == loop_thread and threads["sample_motors"] == loop_thread
    assert loop_thread.isdisjoint(threads["check_program_text"] | threads["draw_plot"])
    assert banks_module.SLICE_LINES * 10 < 450


def test_an_upload_sent_in_slices_is_its_own_sender(
        served: ServiceThread, held_check: threading.Event) -> None:
    """Lines another page sends while an upload goes on in slices never land in its
    bank (the upload is a sender of its own, as a TCP client is)."""
    held_check.set()
    text = "\n".join(["B3.1", *(f"T{n % 8 + 1}.1" for n in range(300)), "END"])

    async def uploader(ws: Any) -> dict[str, Any]:
        return await ask(ws, {"t": "bank_upload", "motor": 1, "text": text}, timeout=60)

    async def chatter(ws: Any) -> None:
        for n in range(40):
            await ask(ws, {"t": "cml", "line": f"P{300 + n}.1=1"}, rid=n)

    async def both() -> list[Any]:
        url = served.transports[1].url
        return list(await asyncio.gather(page(url, uploader), page(url, chatter)))
    upload, _ = run(both())
    assert upload["ok"] and upload["uploaded"] and upload["differences"] == []


def test_the_pages_recording_keeps_its_last_hour_only() -> None:
    """Recording from the page grew for as long as it ran (0.75 MiB a minute with two
    motors moving); it now keeps the last hour of virtual time: after five hours of
    moves it holds what it held after two, and a download starts an hour back."""
    from coolmuscle.chain import Chain
    from coolmuscle.tools.trace.recorder import record
    from coolmuscle.tools.web.traces import RECORD_WINDOW_S, forget_old, trace_rows

    chain = Chain(motors=2)
    recorder = record(chain)
    for line in ("S.1=100", "A.1=100", "S.2=100", "A.2=100"):
        chain.execute(line)
    held = []
    for minute in range(5 * 60):
        for n in range(4):                     # two moves a minute each way, both motors
            chain.execute(f"P.1={20000 * (n % 2)}, ^.1, P.2={-30000 * (n % 2)}, ^.2")
            chain.kernel.run(until=chain.kernel.now + 15 * 10**9)
        forget_old(recorder)
        if minute in (2 * 60 - 1, 5 * 60 - 1):
            held.append(sum(len(t.state_times()) + len(t.piece_starts())
                            for t in recorder.traces.values()))
    assert held[0] > 0 and abs(held[1] - held[0]) <= held[0] * 0.02, held
    assert recorder.start == chain.kernel.now - int(RECORD_WINDOW_S * 1e9)
    _, rows = trace_rows(recorder, 60.0, chain.kernel.now)
    assert next(iter(rows))[0] == recorder.start / 1e9


def test_a_text_of_thousands_of_errors_gets_an_answer_of_200_findings(
        served: ServiceThread) -> None:
    """A 48 KiB text with an error on every line: the answer lists the first 200 (errors
    first) and says how many more, not half a megabyte of findings."""
    text = "\n".join(["B1.1", *("P.1=(((" for _ in range(6000)), "END"])[:48000]

    async def body(ws: Any) -> dict[str, Any]:
        return await ask(ws, {"t": "bank_upload", "motor": 1, "text": text}, timeout=60)
    answer = run(page(served.transports[1].url, body))
    assert answer["ok"] and answer["uploaded"] is False
    found = answer["diagnostics"]
    assert len(found) == 201 and all(d["severity"] == "error" for d in found[:200])
    assert found[-1]["rule"] == "more" and found[-1]["message"].endswith(
        "more findings (coolmuscle check lists them all)")
    assert len(json.dumps(answer)) < 64 * 1024

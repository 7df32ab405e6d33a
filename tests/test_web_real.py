"""The page of a real motor in a real browser, on a stand-in for the motor.

``coolmuscle sim --pty-link LINK --pace`` stands in for a COOL MUSCLE behind a serial
adapter at 38.4 kbps (a subprocess on a pty of its own, wire-paced at its K20 rate, torn
down after each test); ``coolmuscle web LINK`` serves the page (a subprocess too) and
Chromium (Playwright, Debian's chromium) drives it.  What the page did is read back on
the stand-in's own TCP host line, a second door into the same motor (6.6 queries):

* the page says "real", on the pty and over TCP (HOST:PORT);
* a K edit reaches the motor, an out-of-range one is refused before it is sent, and
  after ``$`` it survives a restart of the stand-in (its state directory; the page scans
  the line again and reads it back);
* jog moves it; an alarm injected through the stand-in's own dashboard (over current,
  Ux=64, reported by K23 1) is cleared by the alarm reset button;
* the console is answered while the poll runs;
* bad input gets one clear message: no motor (the stand-in gone), a wrong baud rate,
  a backup of another firmware, a K out of range; one line from the command.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import re
import signal
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from fixtures import Program, SimFactory, run_coolmuscle
from web_support import HostLine, chromium, output_dir, require_browser

playwright = require_browser()

expect = playwright.expect
pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]

TITLE = "ID1 : CM2v3.10R.1 #0802A12345"


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    yield from chromium(playwright)


@pytest.fixture
def web_page(tmp_path: Path) -> Iterator[Callable[..., tuple[Program, str]]]:
    """``web_page(PORT, *options)``: ``coolmuscle web PORT --listen 0`` started, its URL."""
    started: list[Program] = []

    def start(target: str, *options: str) -> tuple[Program, str]:
        program = Program(["web", target, "--listen", "0", *options],
                          tmp_path / f"web{len(started)}.log")
        started.append(program)
        return program, program.wait_for(r"web: (http://\S+)", 60).group(1)
    yield start
    for program in started:
        program.close()


class Page:
    """A page of the dashboard and the console errors it logged."""

    def __init__(self, browser: Any, url: str) -> None:
        self.context = browser.new_context(viewport={"width": 1280, "height": 900},
                                           accept_downloads=True)
        self.page = self.context.new_page()
        self.errors: list[str] = []
        self.page.on("console", lambda m: self.errors.append(f"{m.type}: {m.text}")
                     if m.type == "error" else None)
        self.page.on("pageerror", lambda e: self.errors.append(f"pageerror: {e}"))
        self.page.goto(url)
        expect(self.by("connection")).to_have_text("connected", timeout=10_000)

    def by(self, test_id: str) -> Any:
        return self.page.get_by_test_id(test_id)

    def type_line(self, line: str) -> None:
        box = self.by("cml-input")
        box.fill(line)
        box.press("Enter")

    def close(self) -> None:
        self.context.close()


@pytest.fixture
def pages(browser: Any) -> Iterator[Callable[[str], Page]]:
    opened: list[Page] = []

    def open_page(url: str) -> Page:
        opened.append(Page(browser, url))
        return opened[-1]
    yield open_page
    for page in opened:
        page.close()


def _query(port: int, line: str, answer: str) -> str:
    host = HostLine(port)
    try:
        return host.query(line, answer, timeout=10)
    finally:
        host.close()


def test_pty_page_says_real_and_a_k_edit_survives_a_restart_after_save(
        served_sim: SimFactory, web_page: Callable[..., tuple[Program, str]],
        pages: Callable[[str], Page], tmp_path: Path) -> None:
    """ch. 3 K24 (10..50000, factory 1000); 2.1.2 ``$`` keeps it through a power cycle."""
    link, state = tmp_path / "motor", tmp_path / "state"
    sim = served_sim("--pace", pty=link, state=state)
    _, url = web_page(str(link))
    page = pages(url)
    expect(page.by("line-badge")).to_have_text(f"real motor on {link} at 38.4 kbps")
    expect(page.by("line-badge")).to_have_class(re.compile(r"\breal\b"))
    expect(page.by("wire-door")).to_be_hidden()          # wire faults: a virtual motor's
    expect(page.by("position-1")).to_have_text(re.compile(r"^-?\d+$"), timeout=10_000)
    page.by("k-read").click()
    expect(page.by("k-value-24")).to_have_value("1000", timeout=10_000)
    expect(page.by("k-changed-24")).to_have_text("")
    page.by("k-value-24").fill("5")
    page.by("k-write-24").click()
    expect(page.by("k-note")).to_have_text("K24=5 is out of range (10..50000)")
    assert _query(sim.port, "K24.1", r"K24\.1=-?\d+") == "K24.1=1000"     # nothing sent
    page.by("k-value-24").fill("2000")
    page.by("k-write-24").click()
    expect(page.by("k-changed-24")).to_have_text("changed", timeout=10_000)
    assert _query(sim.port, "K24.1", r"K24\.1=-?\d+") == "K24.1=2000"
    page.by("k-save").click()
    expect(page.by("k-note")).to_have_text("saved.1", timeout=10_000)
    page.page.evaluate("window.scrollTo(0, 0)")
    page.page.screenshot(path=str(output_dir() / "web-real-k-editor.png"), full_page=True)
    assert sim.stop() == 0                          # Ctrl-C: a clean stop
    expect(page.by("line-state")).to_contain_text("the line failed", timeout=10_000)
    page.by("desk-scan").click()                   # no motor: said on the page
    expect(page.by("desk-result")).to_contain_text(f"cannot open {link}", timeout=30_000)
    again = served_sim("--pace", pty=link, state=state)
    page.by("desk-scan").click()
    expect(page.by("desk-result")).to_contain_text(f"ID1  K20=0 (38400 bit/s)  cm2  {TITLE}",
                                                   timeout=30_000)
    page.by("k-read").click()
    expect(page.by("k-value-24")).to_have_value("2000", timeout=10_000)
    expect(page.by("k-changed-24")).to_have_text("changed")
    assert _query(again.port, "K24.1", r"K24\.1=-?\d+") == "K24.1=2000"
    assert page.errors == []


async def _inject(web_url: str, fault: str) -> dict[str, Any]:
    """A fault through the stand-in's own dashboard (its WebSocket, docs/web.md)."""
    import aiohttp

    from web_support import ask, ws_frames
    async with aiohttp.ClientSession() as session, session.ws_connect(web_url + "ws") as ws:
        await ws_frames(ws, lambda f: f["t"] == "hello", timeout=10)
        return await ask(ws, {"t": "fault", "motor": 1, "fault": fault, "params": {}})


def test_jog_moves_it_and_alarm_reset_clears_an_injected_alarm(
        served_sim: SimFactory, web_page: Callable[..., tuple[Program, str]],
        pages: Callable[[str], Page], tmp_path: Path) -> None:
    """Jog: ``P.1+=500, ^.1`` (6.2 relative data, 2.1.1); over current is Ux=64 (6.6 ?99),
    reported by K23 1; ``(`` clears it (docs/fidelity.md "Web dashboard")."""
    link = tmp_path / "motor"
    sim = served_sim("--pace", pty=link, web=True)
    _, url = web_page(str(link))
    page = pages(url)
    start = int(_query(sim.port, "?96.1", r"Px\.1=-?\d+").split("=")[1])
    page.by("jog-step-1").fill("500")
    page.by("jog-plus-1").click()
    expect(page.by("motion-note-1")).to_contain_text("P.1+=500, ^.1 → Ux=0 moving")
    expect(page.by("position-1")).to_have_text(str(start + 500), timeout=15_000)
    expect(page.by("status-1")).to_contain_text("in position", timeout=10_000)
    assert _query(sim.port, "?96.1", r"Px\.1=-?\d+") == f"Px.1={start + 500}"
    with concurrent.futures.ThreadPoolExecutor(1) as pool:    # Playwright's loop is here
        assert pool.submit(asyncio.run, _inject(sim.web_url, "over_current")).result()["ok"]
    expect(page.by("status-1")).to_contain_text("over current", timeout=10_000)
    expect(page.by("log")).to_contain_text("Ux.1=64")
    page.by("alarm-reset-1").click()
    expect(page.by("motion-note-1")).to_have_text("(.1 → Ux=8 in position", timeout=10_000)
    expect(page.by("status-1")).to_contain_text("in position", timeout=10_000)
    assert _query(sim.port, "?99.1", r"Ux\.1=\d+") == "Ux.1=8"
    page.page.evaluate("window.scrollTo(0, 0)")
    page.page.screenshot(path=str(output_dir() / "web-real-alarm-reset.png"))
    assert page.errors == []


def test_over_tcp_the_page_says_real_and_the_console_is_answered_while_polling(
        served_sim: SimFactory, web_page: Callable[..., tuple[Program, str]],
        pages: Callable[[str], Page]) -> None:
    sim = served_sim("--pace", "--motors", "2")
    program, url = web_page(f"127.0.0.1:{sim.port}")
    page = pages(url)
    expect(page.by("line-badge")).to_have_text(
        f"2 real motors on socket://127.0.0.1:{sim.port} (K20 38.4 kbps)")
    expect(page.by("position-2")).to_have_text(re.compile(r"^-?\d+$"), timeout=10_000)
    for n in range(5):
        page.type_line(f"P{n + 1}.2={100 * (n + 1)}")
    page.type_line("?P.2")
    expect(page.by("log")).to_contain_text("< P1.2=100, P2.2=200, P3.2=300, P4.2=400",
                                           timeout=10_000)           # 6.6: 4 a line
    expect(page.by("log")).to_contain_text("< P5.2=500, P6.2=0, P7.2=0, P8.2=0")
    assert _query(sim.port, "P5.2", r"P5\.2=-?\d+") == "P5.2=500"
    assert page.errors == []
    assert program.signal(signal.SIGINT) == 0                 # Ctrl-C: a clean stop
    assert "Traceback" not in program.text


def test_bad_input_gets_one_clear_message_on_the_page_and_one_line_from_the_command(
        served_sim: SimFactory, web_page: Callable[..., tuple[Program, str]],
        pages: Callable[[str], Page], tmp_path: Path, closed_port: int) -> None:
    link = tmp_path / "motor"
    served_sim("--pace", pty=link)
    wrong = run_coolmuscle("web", str(link), "--baud", "9600", "--listen", "0")
    assert wrong.returncode == 2
    assert wrong.stderr == (f"coolmuscle: error: no motor answers on {link} at 9600 bit/s "
                            "(?85.1 within 0.3 s); a wrong --baud? (without it every K20 "
                            "rate is tried)\n")
    missing = run_coolmuscle("web", str(link), "--twin", str(tmp_path / "missing.toml"))
    assert missing.returncode == 2 and missing.stderr.count("\n") == 1
    assert missing.stderr.startswith("coolmuscle: error: cannot read machine file ")
    absent = run_coolmuscle("web", f"127.0.0.1:{closed_port}", "--listen", "0")
    assert absent.returncode == 2 and absent.stderr.count("\n") == 1
    assert absent.stderr.startswith(f"coolmuscle: error: cannot open socket://127.0.0.1:"
                                    f"{closed_port}")
    _, url = web_page(str(link))
    page = pages(url)
    page.page.select_option("#desk-baud", "9600")            # a wrong rate
    page.by("desk-scan").click()
    expect(page.by("desk-result")).to_have_text(
        f"no motor answers on {link} at 9600 bit/s (?85.1 within 0.3 s); a wrong --baud? "
        "(without it every K20 rate is tried)", timeout=30_000)
    page.type_line("?96.1")                                  # the line is as it was
    expect(page.by("log")).to_contain_text(re.compile(r"<\s+Px\.1=-?\d+"), timeout=10_000)
    backup = tmp_path / "rt3.cml"                            # another firmware's backup
    made = run_coolmuscle("backup", "coolmuscle://?firmware=rt3&mode=fast", "-o",
                          str(backup))
    assert made.returncode == 0, made.stderr
    page.by("desk-file").set_input_files(str(backup))
    page.by("desk-restore").click()
    expect(page.by("desk-result")).to_have_text(
        f"rt3.cml holds ID1 of rt3 (ID1 : CM1v3.00R.1 #0000A00000), {link}'s ID1 is cm2 "
        f"({TITLE}): K85, K87 do not apply there; nothing written", timeout=30_000)
    with page.page.expect_download(timeout=60_000) as download:  # the backup, downloaded
        page.by("desk-backup").click()
    saved = tmp_path / "motor.cml"
    download.value.save_as(saved)
    text = saved.read_text()
    assert text.startswith(f"# coolmuscle backup of {link} at 38400 bit/s, ")
    assert f"# == {TITLE}\n" in text and "\nK24.1=1000\n" in text
    page.by("desk-file").set_input_files(str(saved))          # and restored, as it is
    page.by("desk-restore").click()
    expect(page.by("desk-result")).to_contain_text("restored (not saved", timeout=60_000)
    expect(page.by("desk-result")).to_contain_text("ID1 K parameters: as in the backup, "
                                                   "nothing to write")
    page.by("k-read").click()
    page.by("k-value-57").fill("99999")                      # ch. 3 K57: 100..10000
    page.by("k-write-57").click()
    expect(page.by("k-note")).to_have_text("K57=99999 is out of range (100..10000)")
    assert page.errors == []

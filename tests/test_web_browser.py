"""The dashboard in a real browser: Playwright driving Debian's chromium (docs/web.md).

Each check is read back on the motor's own TCP host line, an independent door into the
same chain (6.6 queries ``?70`` ``?99`` ``?#``).  Screenshots go to the test output
directory (``$COOLMUSCLE_TEST_OUTPUT``, default out/test-web).
"""

from __future__ import annotations

import importlib.util
import os
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from web_support import ROOT, HostLine, chromium, output_dir, require_browser, serve

playwright = require_browser()

expect = playwright.expect


@pytest.fixture(scope="module")
def browser():
    yield from chromium(playwright)


@pytest.fixture(scope="module")
def served():
    st = serve(motors=3)
    yield st
    st.stop()


@pytest.fixture()
def host(served):
    line = HostLine(served.transports[0].info()["port"])
    yield line
    line.close()


class Page:
    """A page of the dashboard and the console errors it logged."""

    def __init__(self, browser, url: str, width: int = 1280, height: int = 800,
                 context=None) -> None:
        self.own = context is None
        self.context = context or browser.new_context(viewport={"width": width,
                                                               "height": height})
        self.page = self.context.new_page()
        self.page.add_init_script("window.addEventListener('unhandledrejection',"
                                  " (e) => console.error('unhandled rejection: ' + e.reason));")
        self.errors: list[str] = []
        self.page.on("console", lambda m: self.errors.append(f"{m.type}: {m.text}")
                     if m.type == "error" else None)
        self.page.on("pageerror", lambda e: self.errors.append(f"pageerror: {e}"))
        self.page.goto(url)
        expect(self.by("connection")).to_have_text("connected", timeout=10_000)

    def by(self, test_id: str):
        return self.page.get_by_test_id(test_id)

    def type_line(self, line: str) -> None:
        box = self.by("cml-input")
        box.click()
        box.press_sequentially(line, delay=0)
        box.press("Enter")

    def number(self, test_id: str) -> int:
        return int(self.by(test_id).inner_text())

    def close(self) -> None:
        if self.own:
            self.context.close()
        else:
            self.page.close()


@pytest.fixture()
def page(browser, served):
    p = Page(browser, served.transports[1].url)
    yield p
    p.close()


def test_page_loads_without_console_errors_and_every_control_has_a_name(page):
    expect(page.by("position-1")).to_have_text(re.compile(r"-?\d+"))
    expect(page.by("chart-3").locator("canvas").first).to_be_visible()
    unnamed = page.page.evaluate("""() => [...document.querySelectorAll(
        'button, input, select, textarea, a[href], canvas[role]')].filter(el => {
          const named = el.getAttribute('aria-label') || (el.labels && el.labels.length)
                        || el.textContent.trim();
          return !named && el.offsetParent !== null;
        }).map(el => el.outerHTML.slice(0, 80))""")
    assert unnamed == []
    assert page.errors == []


def test_keyboard_only_console_and_input_toggle(page, host):
    """Keyboard: the first Tab reaches "skip to the console", Enter puts the caret in
    the CML line; a focused input toggle flips with Space (6.6 ?70)."""
    page.page.keyboard.press("Tab")
    page.page.keyboard.press("Enter")
    assert page.page.evaluate("() => document.activeElement.dataset.testid") == "cml-input"
    page.page.keyboard.type("?97.1")
    page.page.keyboard.press("Enter")
    expect(page.by("log")).to_contain_text(re.compile(r"<\s+Sx\.1="))
    before = int(host.query("?70.1", r"IN\.1=[0-9A-Fa-f]+").split("=")[1], 16)
    page.by("input-1-5").focus()
    page.page.keyboard.press("Space")
    expect(page.by("input-1-5")).to_have_attribute("aria-pressed", "true")
    assert int(host.query("?70.1", r"IN\.1=[0-9A-Fa-f]+").split("=")[1], 16) == before | 0x10
    page.page.keyboard.press("Space")
    expect(page.by("input-1-5")).to_have_attribute("aria-pressed", "false")


def test_move_typed_in_console_shows_position_rising_and_ux8_in_log(page, host):
    """2.1 example: S, A, P then ^ (cml-users-guide.txt 2.1.1); Ux.1=8 when in position."""
    start = page.number("position-1")
    page.type_line(f"S.1=20, A.1=100, P.1={start + 5000}, ^.1")     # about 4 s
    seen = []
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and (not seen or seen[-1] < start + 5000):
        seen.append(page.number("position-1"))
        time.sleep(0.05)
    rising = sorted(set(seen))
    assert len([v for v in rising if start < v < start + 5000]) >= 3, seen   # live, not one jump
    assert seen == sorted(seen)
    expect(page.by("log")).to_contain_text("Ux.1=8", timeout=5000)
    expect(page.by("status-1")).to_contain_text("in position")
    assert host.query("?96.1", r"Px\.1=-?\d+") == f"Px.1={start + 5000}"
    assert page.errors == []


def test_input_toggle_changes_query_70_on_the_tcp_line(page, host):
    """6.6 ?70: the input word; input 3 is bit 2 (IN.n=04)."""
    before = host.query("?70.1", r"IN\.1=[0-9A-Fa-f]+")
    page.by("input-1-3").click()
    expect(page.by("input-1-3")).to_have_attribute("aria-pressed", "true")
    after = host.query("?70.1", r"IN\.1=[0-9A-Fa-f]+")
    assert int(after.split("=")[1], 16) == int(before.split("=")[1], 16) | 0x04
    page.by("input-1-3").click()
    expect(page.by("input-1-3")).to_have_attribute("aria-pressed", "false")
    assert host.query("?70.1", r"IN\.1=[0-9A-Fa-f]+") == before


def test_alarm_injected_from_the_page_shows_in_status_and_query_99(page, host):
    """docs/machine-file.md "Faults": over_current is Ux=64 at once (6.6 ?99)."""
    page.page.select_option("#fault-motor", "2")
    page.by("fault-over_current").click()
    expect(page.by("status-2")).to_contain_text("over current", timeout=5000)
    ux = int(host.query("?99.2", r"Ux\.2=\d+").split("=")[1])
    assert ux & 64
    expect(page.by("log")).to_contain_text(re.compile(r"Ux\.2=\d+"))
    page.type_line("(.2")                         # alarm reset (2.1.2 "(")
    expect(page.by("status-2")).not_to_contain_text("over current", timeout=5000)


def test_bank_uploaded_from_the_page_reads_back_with_query_1(page, host):
    """2.2.2 program bank definition; 6.6 ?#.n lists it."""
    page.page.select_option("#bank-motor", "3")
    page.by("bank-text").fill("S1.3=50\nA1.3=100\nP1.3=2000\nB1.3\nS1.3, A1.3, P1.3\nEND")
    page.by("bank-upload").click()
    expect(page.by("bank-verdict")).to_contain_text("read back identical", timeout=5000)
    expect(page.by("bank-findings").locator("li")).to_have_count(0)
    assert host.query("?1.3", r"S1\.3.*") == "S1.3, A1.3, P1.3"
    assert host.query("?P1.3", r"P1\.3=.*").startswith("P1.3=2000,")  # the data line ran too
    page.by("bank-start").click()                                      # [1.3 (6.5)
    expect(page.by("log")).to_contain_text("[1.3")
    expect(page.by("position-3")).to_have_text("2000", timeout=10_000)
    assert host.query("?96.3", r"Px\.3=-?\d+") == "Px.3=2000"


def test_checker_errors_are_shown_on_their_line_and_nothing_is_sent(page, host):
    page.page.select_option("#bank-motor", "3")
    page.by("bank-text").fill("B4.3\nS1.3\nP1.3=(((\nEND")
    page.by("bank-upload").click()
    expect(page.by("bank-result")).to_contain_text("line 3", timeout=5000)
    expect(page.by("bank-verdict")).to_have_text("not uploaded")
    # the findings are numbered; the outcome is not one of them
    findings = page.by("bank-findings").locator("li").all_inner_texts()
    assert findings and all(re.match(r"line \d+:\d+ (error|warning): ", f) for f in findings)
    page.by("bank-result").get_by_role("button", name=re.compile(r"line 3:.*error")).click()
    selected = page.page.evaluate(
        "() => { const t = document.getElementById('bank-text');"
        " return t.value.slice(t.selectionStart, t.selectionEnd); }")
    assert selected == "P1.3=((("
    assert "B4.3" not in _listing(host, 3)


def test_bad_input_from_the_page_gets_an_error_never_a_stuck_page(page, host):
    page.type_line("P.1=(((")
    expect(page.page.locator("#cml-note")).to_contain_text("not CML")
    expect(page.by("log")).to_contain_text("not CML", timeout=5000)
    log = page.by("log").inner_text()          # the note after its line, not before
    assert log.index("> P.1=(((") < log.index("! not CML")
    page.type_line("K23.1=17")                    # ch. 3 K23 +16: error messages
    page.type_line("P.1=999999999")
    expect(page.by("log")).to_contain_text("error00.1", timeout=5000)
    page.type_line("K23.1=1")
    page.page.evaluate("() => { document.getElementById('bank-text').value ="
                       " 'B9.1\\n' + 'T1.1\\n'.repeat(12000) + 'END'; }")   # ~60 KB pasted
    page.by("bank-upload").click()
    expect(page.by("bank-result")).to_contain_text("too long")
    page.page.evaluate("() => { document.getElementById('bank-text').value ="
                       " 'B9.1\\n' + '\\u0001'.repeat(47000) + '\\nEND'; }")  # 6 bytes each
    page.by("bank-upload").click()
    expect(page.by("bank-result")).to_contain_text("too large to send")
    expect(page.by("connection")).not_to_contain_text("disconnected")   # the socket lives on
    page.page.evaluate("() => window.__huge = 1")   # the page still runs scripts
    page.page.select_option("#fault-motor", "1")
    page.page.fill("[data-testid=fault-stuck_input-input]", "99")
    page.by("fault-stuck_input").click()
    expect(page.page.locator("#fault-note")).to_contain_text("1..6")
    page.type_line("?99.1")
    expect(page.by("log")).to_contain_text(re.compile(r"<\s+Ux\.1=\d+"))
    expect(page.by("connection")).to_have_text("connected")
    assert page.errors == []


def _listing(host: HostLine, motor: int) -> list[str]:
    """``?1000.n`` (6.6): every bank, ending with the ``Commands.n:`` summary line."""
    host.sock.sendall(f"?1000.{motor}\r".encode())
    lines = []
    while not lines or not lines[-1].startswith(f"Commands.{motor}"):
        lines.append(host.wait_for(r".+"))
    return lines


def test_tab_closed_mid_upload_leaves_a_whole_bank_or_none(browser, served, host):
    body = [f"T{n % 10 + 1}.1" for n in range(400)]
    a = Page(browser, served.transports[1].url)
    a.page.select_option("#bank-motor", "1")
    a.by("bank-text").fill("\n".join(["B5.1", *body, "END"]))
    a.by("bank-upload").click()
    a.close()                                     # the tab goes away at once
    listing = _listing(host, 1)
    if "B5.1" in listing:                         # the request arrived whole: all of it
        start = listing.index("B5.1")
        assert listing[start + 1:start + 401] == body and listing[start + 401] == "END.1"
    b = Page(browser, served.transports[1].url)   # the server and other pages go on
    try:
        b.type_line("?99.1")
        expect(b.by("log")).to_contain_text(re.compile(r"Ux\.1=\d+"), timeout=5000)
        assert b.errors == []
    finally:
        b.close()


def test_record_then_download_trace_and_plot_from_the_page(browser, tmp_path: Path):
    st = serve(motors=1)                          # a chain of its own: nothing recorded yet
    page = Page(browser, st.transports[1].url)
    try:
        _record_and_download(page)
    finally:
        page.close()
        st.stop()


def _record_and_download(page: Page) -> None:
    page.page.click("#dl-csv")                   # before Record: a clear message, no file
    expect(page.page.locator("#download-note")).to_contain_text("press Record first")
    page.by("record").click()
    expect(page.page.locator("#record-state")).to_contain_text("recording")
    page.type_line("S.1=100, A.1=100, P.1=-500, ^.1")
    expect(page.by("log")).to_contain_text("trace recording started")
    time.sleep(0.5)
    with page.page.expect_download() as csv_download:
        page.page.click("#dl-csv")
    csv = Path(csv_download.value.path()).read_text()
    assert csv.startswith("time_s,m1.") and len(csv.splitlines()) > 10
    with page.page.expect_download() as png_download:
        page.page.click("#dl-png")
    assert Path(png_download.value.path()).read_bytes()[:4] == b"\x89PNG"
    if importlib.util.find_spec("pyarrow") is None:
        page.page.click("#dl-parquet")
        expect(page.page.locator("#download-note")).to_contain_text("pyarrow")
    else:
        with page.page.expect_download() as parquet_download:
            page.page.click("#dl-parquet")
        assert Path(parquet_download.value.path()).read_bytes()[:4] == b"PAR1"
    assert [e for e in page.errors if "409" not in e] == []


def test_ten_open_tabs_all_follow_a_move(browser, served, host):
    context = browser.new_context(viewport={"width": 800, "height": 600})
    tabs = [Page(browser, served.transports[1].url, context=context) for _ in range(10)]
    try:
        start = tabs[0].number("position-2")
        tabs[3].type_line(f"S.2=300, A.2=300, P.2={start + 3000}, ^.2")
        for tab in tabs:
            expect(tab.by("position-2")).to_have_text(str(start + 3000), timeout=10_000)
            expect(tab.by("log")).to_contain_text("Ux.2=8")
        assert host.query("?96.2", r"Px\.2=-?\d+") == f"Px.2={start + 3000}"
        assert all(tab.errors == [] for tab in tabs)
    finally:
        context.close()


def test_screenshots_desktop_and_phone(browser, served, host):
    """1280x800 and 390x844 PNGs in the test output (looked at by a person; docs/web.md)."""
    out = output_dir()
    shots = []
    for width, height, name in ((1280, 800, "web-1280x800.png"), (390, 844, "web-390x844.png")):
        p = Page(browser, served.transports[1].url, width, height)
        try:
            p.type_line("?96.1")
            p.type_line(f"S.1=20, A.1=40, P.1={p.number('position-1') + 8000}, ^.1")
            p.type_line(f"S.2=40, A.2=40, P.2={p.number('position-2') - 3000}, ^.2")
            time.sleep(1.6)
            p.page.evaluate("() => { document.activeElement.blur(); window.scrollTo(0, 0); }")
            p.page.screenshot(path=str(out / name))
            shots.append(out / name)
            overflow = p.page.evaluate("() => document.documentElement.scrollWidth"
                                       " - document.documentElement.clientWidth")
            assert overflow <= 0, f"{name}: the page is {overflow}px wider than the screen"
            assert p.errors == []
        finally:
            p.close()
    for shot in shots:
        assert shot.stat().st_size > 10_000 and shot.read_bytes()[:4] == b"\x89PNG"


# -- the command line: a restarted simulator, run --web --------------------------------
def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _coolmuscle(*args: str) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    return subprocess.Popen([sys.executable, "-m", "coolmuscle", *args], env=env,
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _wait_banner(proc: subprocess.Popen, word: str, timeout: float = 20) -> str:
    deadline = time.monotonic() + timeout
    seen = ""
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        if not line:
            break
        seen += line
        if word in line:
            return seen
    proc.kill()
    raise AssertionError(f"no {word!r} in the banner: {seen!r}")


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5)


def test_page_reconnects_after_a_restart_of_the_sim(browser):
    port = _free_port()
    sim = _coolmuscle("sim", "--no-state", "--tcp", "0", "--web", str(port))
    try:
        _wait_banner(sim, "web: http://127.0.0.1:")
        p = Page(browser, f"http://127.0.0.1:{port}/")
        p.type_line("P.1=100")
        _stop(sim)
        expect(p.by("connection")).to_contain_text("reconnecting", timeout=10_000)
        sim = _coolmuscle("sim", "--no-state", "--tcp", "0", "--web", str(port))
        _wait_banner(sim, "web: http://127.0.0.1:")
        expect(p.by("connection")).to_have_text("connected", timeout=15_000)
        p.type_line("?99.1")
        expect(p.by("log")).to_contain_text("Ux.1=8", timeout=5000)
        assert [e for e in p.errors if "WebSocket" not in e and "ERR_CONNECTION" not in e] == []
        p.close()
    finally:
        _stop(sim)


def test_sim_web_on_all_interfaces_asks_for_the_printed_token(browser):
    port = _free_port()
    sim = _coolmuscle("sim", "--no-state", "--tcp", "0", "--web", f"0.0.0.0:{port}")
    try:
        banner = _wait_banner(sim, "token:")
        token = re.search(r"token: (\S+)\)", banner).group(1)
        context = browser.new_context()
        page = context.new_page()
        page.goto(f"http://127.0.0.1:{port}/")
        expect(page.locator("#token-dialog")).to_be_visible()
        page.fill("#token-input", token)
        page.click("#token-form button")
        expect(page.get_by_test_id("connection")).to_have_text("connected", timeout=10_000)
        expect(page.get_by_test_id("position-1")).to_have_text("0")
        context.close()
    finally:
        _stop(sim)


def test_run_script_web_plays_the_script_live(browser, tmp_path: Path):
    script = tmp_path / "move.cml"
    # Ux=8 comes inside the K55 window, before the shaft has settled (docs/fidelity.md K55):
    # the position is read once it has
    script.write_text("S.1=100\nA.1=100\nP.1=3000\n^.1\n@until Ux.1=8 5\n@wait 0.3\n?96.1\n")
    port = _free_port()
    run = _coolmuscle("run", str(script), "--web", str(port))
    try:
        _wait_banner(run, "starts when a page connects")
        p = Page(browser, f"http://127.0.0.1:{port}/")
        expect(p.by("log")).to_contain_text("Ux.1=8", timeout=10_000)
        expect(p.by("position-1")).to_have_text("3000")
        _wait_banner(run, "script done")
        p.close()
    finally:
        _stop(run)
    out = run.stdout.read()
    assert "< Px.1=3000" in out and "> ^.1" in out


def test_another_sites_img_of_the_plot_is_refused(browser, served):
    """A page of another site (``localhost`` is another site than ``127.0.0.1``; another
    port of the same host is ``same-site``) showing ``<img src=".../api/plot.png">``:
    Chromium's request is refused (403, nothing drawn) while the page's own download
    link works."""
    import http.server
    import threading

    web = served.transports[1]
    served.call(web.start_recording)
    target = web.url + "api/plot.png"
    html = f'<img id="a" src="{target}"><img id="b" src="{target}?x=1">'.encode()

    class Evil(http.server.BaseHTTPRequestHandler):
        def do_GET(self):                                       # noqa: N802
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.end_headers()
            self.wfile.write(html)

        def log_message(self, *args):
            pass
    evil = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Evil)
    threading.Thread(target=evil.serve_forever, daemon=True).start()
    context = browser.new_context()
    try:
        tab = context.new_page()
        for host in ("localhost", "127.0.0.1"):            # cross-site, then same-site
            tab.goto(f"http://{host}:{evil.server_address[1]}/")
            tab.wait_for_load_state("load")
            widths = tab.evaluate("[...document.images].map((i) => i.naturalWidth)")
            assert widths == [0, 0], (host, widths)
        assert web.cross_site_refused >= 4
        tab.goto(web.url)                                  # the page's own: served
        width = tab.evaluate("""(src) => new Promise((done) => {
            const img = new Image(); img.onload = () => done(img.naturalWidth);
            img.onerror = () => done(-1); img.src = src; })""", target)
        assert width > 0
    finally:
        context.close()
        evil.shutdown()

"""The dashboard's wire-fault panel in a real browser (Playwright, Debian's chromium):
every door and kind of the vocabulary is offered, a fault installed from the page acts
on the motor's own TCP host line (an independent door into the same chain), shows in
the page's log and list, and ends from the page (docs/wire-faults.md, docs/web.md).
"""

from __future__ import annotations

import re

import pytest

from coolmuscle.device.wire import describe
from test_web_browser import Page, expect, playwright
from web_support import HostLine, chromium, serve


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


@pytest.fixture()
def page(browser, served):
    p = Page(browser, served.transports[1].url)
    yield p
    p.close()


@pytest.fixture(autouse=True)
def no_faults_left(served):
    yield
    served.call(lambda: served.chain.clear_wire_faults())


#: A query whose answer no test here waits for: it marks where the line is in step again.
MARK, MARK_ANSWER = "?99.1", r"Ux\.1=\d+"


def silent(host: HostLine, line: str, answer: str, within: float = 1.0) -> bool:
    """Send ``line``: True when nothing but its echo comes back within ``within`` s,
    False when ``answer`` does; any other line fails.  Then ``MARK`` to ID1, read up to
    its answer: a reply arriving after the window is caught there (it fails) instead of
    being taken by the next query for its own."""
    host.sock.sendall(line.encode() + b"\r")
    heard = [t for t in host.lines_within(within) if t != line]     # ID1 echoes the line
    if any(re.fullmatch(answer, t) for t in heard):
        return False
    assert heard == [], f"{line!r}: {heard!r} instead of silence or {answer!r}"
    host.sock.sendall(MARK.encode() + b"\r")
    late = []
    while not re.fullmatch(MARK_ANSWER, text := host.wait_for(r".*", timeout=5)):
        if text and text not in (line, MARK):
            late.append(text)
    assert late == [], f"{line!r}: {late!r} after {within} s of silence"
    return True


def choose(page: Page, door: str, kind: str) -> None:
    page.by("wire-door").select_option(door)
    page.by("wire-kind").select_option(kind)


def test_the_panel_offers_every_door_and_kind_with_named_controls(page):
    doors = describe()
    assert page.by("wire-door").locator("option").all_inner_texts() == list(doors)
    for door, entry in doors.items():
        page.by("wire-door").select_option(door)
        kinds = [k["kind"].replace("_", " ") for k in entry["kinds"]]
        assert page.by("wire-kind").locator("option").all_inner_texts() == kinds
    choose(page, "host-line", "garble")
    expect(page.by("wire-param-byte")).to_be_visible()
    expect(page.by("wire-param-xor")).to_be_visible()
    choose(page, "host-line", "dead")
    expect(page.by("wire-every")).to_be_disabled()            # lasting: from at to until
    choose(page, "ethercat", "link_down")                     # the EtherCAT door's too
    expect(page.by("wire-param-bridge")).to_be_visible()
    expect(page.by("wire-every")).to_be_disabled()
    choose(page, "ethercat", "lost_frame")
    expect(page.by("wire-param-way")).to_be_visible()
    expect(page.by("wire-every")).to_be_enabled()
    unnamed = page.page.evaluate("""() => [...document.querySelectorAll(
        '#wire-h ~ * button, #wire-h ~ * input, #wire-h ~ * select')].filter(el => {
          const named = el.getAttribute('aria-label') || (el.labels && el.labels.length)
                        || el.textContent.trim();
          return !named && el.offsetParent !== null;
        }).map(el => el.outerHTML.slice(0, 80))""")
    assert unnamed == []
    assert page.errors == []


def test_a_drop_installed_from_the_page_loses_one_reply_on_the_tcp_line(page, host):
    assert host.query("?96.1", r"Px\.1=-?\d+")
    choose(page, "host-line", "drop")
    page.by("wire-count").fill("1")
    page.by("wire-inject").click()
    expect(page.page.locator("#wire-note")).to_have_text(
        re.compile(r"wire fault \d+ installed: host-line drop"))
    expect(page.by("wire-list")).to_contain_text("host-line drop")
    assert silent(host, "?96.1", r"Px\.1=-?\d+")
    assert host.query("?96.1", r"Px\.1=-?\d+")                  # count = 1: once
    expect(page.by("log")).to_contain_text(re.compile(r"wire fault \d+ host-line drop: "
                                                      r'"Px\.1=-?\d+\\r\\n" lost'))


def test_power_off_from_the_page_and_back_with_end(page, host):
    choose(page, "chain", "power_off")
    page.by("wire-motor").fill("2")
    page.by("wire-inject").click()
    expect(page.by("wire-list")).to_contain_text("chain power off ID2")
    assert silent(host, "?96.2", r"Px\.2=-?\d+")
    assert host.query("?96.1", r"Px\.1=-?\d+")                  # ID1 still answers
    page.by("wire-list").get_by_role("button").first.click()    # end it
    expect(page.by("wire-list")).not_to_contain_text("power off")
    assert host.query("?96.2", r"Px\.2=-?\d+")
    expect(page.by("log")).to_contain_text(re.compile(r"chain power_off: ends"))


def test_a_bad_parameter_is_refused_with_the_models_words(page, served):
    choose(page, "host-line", "delay")
    page.by("wire-param-ms").fill("-5")
    page.by("wire-inject").click()
    expect(page.page.locator("#wire-note")).to_contain_text("ms must be 0..60000")
    assert served.call(lambda: served.chain.wire_faults.describe()) == []
    assert page.errors == []

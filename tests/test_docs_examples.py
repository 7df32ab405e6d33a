"""Every code block of README.md and docs/ runs as written (what a newcomer meets first).

Blocks are fenced with a language: ``sh`` and ``python`` blocks run, ``toml`` blocks
must parse (a machine file must load), ``text`` blocks (output, pictures, synopses) are
read only.  The commands run the way README.md says to run them: with the virtual
environment active (``coolmuscle`` and ``python`` on PATH, here wrappers for this
checkout's sources), from the top of the checkout (``examples/`` beside), with a fresh
home and state directory.  A note in an HTML comment just before a block says what the
text tells the user to have running:

``<!-- docs-example: sim ARGS -->``
    ``coolmuscle sim ARGS`` serves while the block runs (started once per module for
    consecutive blocks with the same ARGS), on 127.0.0.1 as the text says;
``<!-- docs-example: servers -->``
    each line starts a server: it must print its ready banner (``run --web``: its
    address), then it is stopped;
``<!-- docs-example: continues -->``
    a Python block that goes on from the previous Python block of the same page;
``<!-- docs-example: output -->``
    a ``text`` block that is what the shell block before it prints (stdout, then
    stderr), line for line; a line ``...`` stands for any number of lines;
``<!-- docs-example: synopsis ARGS -->``
    a ``text`` block that names every option ``coolmuscle ARGS --help`` shows, and
    no other;
``<!-- docs-example: hardware -->`` / ``interactive`` / ``setup`` / ``project``
    not run here: a real motor on /dev/ttyUSB0 or a raw network interface, a terminal
    or a second shell a person works in (the EtherCAT lab; its tests run the same
    session), the README's install commands (CI runs those itself), or a command run in
    the reader's own project (tests/test_testing_plugin.py runs the sample project,
    examples/user-project/, the same way).

Blocks in ``yaml`` (a CI job) must parse.

Everything runs in a private network namespace (``unshare -n``, loopback only), so
the documented ports (5150, 1502) are the ones used and nothing else on the machine
can collide with them; it disappears with its last process.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md"] + sorted((ROOT / "docs").glob("*.md"))
_BLOCK = re.compile(r"(?:^<!-- docs-example: (?P<note>[^>]*?) -->\n)?^```(?P<lang>[\w-]*)\n"
                    r"(?P<body>.*?)^```[ \t]*$", re.M | re.S)
RUN_TIMEOUT = 60
READY_TIMEOUT = 15
NOT_RUN = ("hardware", "interactive", "setup", "project")


@dataclass
class Block:
    page: Path
    line: int
    lang: str
    note: str
    body: str

    @property
    def id(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"

    @property
    def kind(self) -> str:
        return self.note.split()[0] if self.note else ""


def _blocks() -> list[Block]:
    found = []
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        for m in _BLOCK.finditer(text):
            line = text.count("\n", 0, m.start("lang")) + 1
            found.append(Block(page, line, m.group("lang"), (m.group("note") or "").strip(),
                               m.group("body")))
    return found


BLOCKS = _blocks()
RUNNABLE = [b for b in BLOCKS if b.lang in ("sh", "python") and b.kind not in NOT_RUN
            and b.kind != "continues"]


def test_every_block_names_its_language_and_notes_are_known() -> None:
    assert len(BLOCKS) > 30
    for block in BLOCKS:
        assert block.lang in ("sh", "python", "toml", "text", "yaml"), block.id
        assert block.kind in ("", "sim", "servers", "continues", "output",
                              "synopsis") + NOT_RUN, block.id
        if block.kind in ("output", "synopsis"):
            assert block.lang == "text", block.id
        if block.kind == "hardware":         # a serial device or a raw network interface
            assert "/dev/tty" in block.body or "--ethercat" in block.body, \
                f"{block.id}: 'hardware' without a device"
    not_run = [b for b in BLOCKS if b.kind in NOT_RUN]
    # the exceptions stay few: a real serial port or NIC, a shell per process, the set-up
    # itself (the two newest, docs/twin.md's capture from /dev/ttyUSB0 and docs/wireshark.md's
    # three-shell EtherCAT capture, are run without hardware by tests/test_twin_loop.py and
    # tests/test_wireshark.py), and the two commands of docs/testing-your-project.md that
    # run in the reader's own project (tests/test_testing_plugin.py runs the sample project);
    # docs/real-motor.md's page on hardware (`coolmuscle web /dev/ttyUSB0`, with and
    # without --twin) is run on a paced pty stand-in by tests/test_web_real.py and
    # tests/test_web_twin.py
    assert len(not_run) <= 20, [b.id for b in not_run]


def _printed(block: Block) -> Block | None:
    """The ``output`` block that follows ``block`` on its page (``None``: none)."""
    page = [b for b in BLOCKS if b.page == block.page]
    after = page[page.index(block) + 1:page.index(block) + 2]
    return after[0] if after and after[0].kind == "output" else None


def _lines_match(expected: list[str], printed: list[str]) -> str:
    """Why ``printed`` is not ``expected`` (``...`` lines skip any lines); "" when it is."""
    at, skipping = 0, False
    for line in expected:
        if line.strip() == "...":
            skipping = True
            continue
        while skipping and at < len(printed) and printed[at] != line:
            at += 1
        if at >= len(printed) or printed[at] != line:
            shown = printed[at] if at < len(printed) else "(the end)"
            return f"expected {line!r}, printed {shown!r}"
        at, skipping = at + 1, False
    if not skipping and at != len(printed):
        return f"printed more: {printed[at]!r}"
    return ""


def test_output_blocks_follow_a_command_and_sudo_names_the_checkouts_command() -> None:
    """Each output block follows the shell block whose output it is; a ``sudo`` line
    names the checkout's command (sudo does not keep an activated environment: plain
    ``sudo coolmuscle`` runs another installation, or none)."""
    for block in BLOCKS:
        if block.kind == "output":
            page = [b for b in BLOCKS if b.page == block.page]
            before = page[page.index(block) - 1]
            assert before.lang == "sh" and before.kind not in NOT_RUN, block.id
        if block.lang == "sh":
            for line in _commands(block.body):
                for word in re.findall(r"\bsudo\s+(?:ip netns exec \S+\s+)?(\S+)", line):
                    assert word not in ("coolmuscle", "python"), f"{block.id}: {line}"


@pytest.mark.parametrize("block", [b for b in BLOCKS if b.kind == "synopsis"],
                         ids=lambda b: b.id)
def test_synopsis_blocks_name_every_option(block: Block) -> None:
    args = block.note.split()[1:]
    done = subprocess.run([sys.executable, "-m", "coolmuscle", *args, "--help"],
                          capture_output=True, text=True, timeout=60,
                          env={**os.environ, "PYTHONPATH": str(ROOT / "src"), "COLUMNS": "200"})
    assert done.returncode == 0, done.stderr
    shown = set(re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", done.stdout)) - {"--help"}
    named = set(re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", block.body))
    assert shown - named == set(), f"{block.id}: missing {sorted(shown - named)}"
    assert named - shown == set(), f"{block.id}: no such option {sorted(named - shown)}"


@pytest.mark.parametrize("block", [b for b in BLOCKS if b.lang == "yaml"], ids=lambda b: b.id)
def test_yaml_blocks_parse(block: Block) -> None:
    import yaml
    assert yaml.safe_load(block.body), block.id


@pytest.mark.parametrize("block", [b for b in BLOCKS if b.lang == "toml"], ids=lambda b: b.id)
def test_toml_blocks_parse_and_machine_files_load(block: Block) -> None:
    data = tomllib.loads(block.body)
    if "axis" in data or "wire" in data:
        from coolmuscle.chain.machine import load_machine
        path = Path(os.environ.get("TMPDIR", "/tmp")) / f"docs-{os.getpid()}.toml"
        path.write_text(block.body, encoding="utf-8")
        try:
            assert load_machine(path) is not None
        finally:
            path.unlink()


# -- the environment the README describes -------------------------------------------
class Env:
    """A checkout-like working directory, PATH with ``coolmuscle`` and ``python``, a
    fresh home, a network namespace, and at most one ``coolmuscle sim`` at a time."""

    def __init__(self, base: Path) -> None:
        self.cwd = base / "checkout"
        self.cwd.mkdir()
        for name in ("examples", "tests", "docs"):
            (self.cwd / name).symlink_to(ROOT / name)
        (self.cwd / "out").mkdir()
        bin_dir = base / "bin"
        bin_dir.mkdir()
        for name, target in (("python", ""), ("coolmuscle", "-m coolmuscle ")):
            wrapper = bin_dir / name
            wrapper.write_text(f'#!/bin/sh\nexec "{sys.executable}" {target}"$@"\n')
            wrapper.chmod(0o755)
        home = base / "home"
        home.mkdir()
        self.env = {"PATH": f"{bin_dir}:/usr/bin:/bin:/usr/sbin:/sbin", "HOME": str(home),
                    "XDG_DATA_HOME": str(home / ".local" / "share"),
                    "XDG_STATE_HOME": str(home / ".local" / "state"),
                    "PYTHONPATH": str(ROOT / "src"), "LANG": "C.UTF-8", "CI": "true",
                    "TMPDIR": str(base), "MPLBACKEND": "Agg", "COLUMNS": "100"}
        self.ns = subprocess.Popen(["unshare", "-n", "sh", "-c",
                                    "ip link set lo up && echo up && exec sleep 3600"],
                                   stdout=subprocess.PIPE, text=True)
        assert self.ns.stdout is not None and self.ns.stdout.readline().strip() == "up"
        self.sim: tuple[str, subprocess.Popen[str], Path] | None = None
        self.base = base

    def command(self, argv: list[str]) -> list[str]:
        return ["nsenter", "-t", str(self.ns.pid), "-n", "--"] + argv

    def run(self, argv: list[str],
            timeout: float = RUN_TIMEOUT) -> subprocess.CompletedProcess[str]:
        return subprocess.run(self.command(argv), cwd=self.cwd, env=self.env, text=True,
                              capture_output=True, timeout=timeout, stdin=subprocess.DEVNULL)

    def start(self, line: str) -> tuple[subprocess.Popen[str], Path]:
        """Start a server command line; returns once it printed ``ready``."""
        log = self.base / f"server-{time.monotonic_ns()}.log"
        with log.open("w") as fh:
            proc = subprocess.Popen(self.command(["bash", "-c", f"exec {line}"]), cwd=self.cwd,
                                    env=self.env, text=True, stdout=fh, stderr=subprocess.STDOUT,
                                    stdin=subprocess.DEVNULL, start_new_session=True)
        deadline = time.monotonic() + READY_TIMEOUT
        while not re.search(r"ready|web: http://", log.read_text()):   # sim / run --web
            if proc.poll() is not None or time.monotonic() > deadline:
                self.stop(proc)
                raise AssertionError(f"{line!r} did not get ready:\n{log.read_text()}")
            time.sleep(0.05)
        time.sleep(0.2)              # the banner's second line (where it listens)
        return proc, log

    @staticmethod
    def stop(proc: subprocess.Popen[str]) -> int:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGINT)
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(timeout=10)
        return proc.returncode

    def use_sim(self, args: str) -> None:
        if self.sim is not None and self.sim[0] == args:
            return
        self.stop_sim()
        proc, log = self.start(f"coolmuscle sim {args}".strip())
        self.sim = (args, proc, log)

    def stop_sim(self) -> None:
        if self.sim is not None:
            _, proc, log = self.sim
            self.sim = None
            code = self.stop(proc)
            text = log.read_text()
            assert "Traceback" not in text and code in (0, 130, -2), text

    def close(self) -> None:
        self.stop_sim()
        self.ns.kill()
        self.ns.wait(timeout=10)


@pytest.fixture(scope="module")
def env(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Env]:
    if os.geteuid() != 0 or not shutil.which("unshare") or not shutil.which("nsenter"):
        pytest.skip("the docs examples run in a private network namespace: needs root, "
                    "unshare and nsenter (CI has them)")
    made = Env(tmp_path_factory.mktemp("docs"))
    yield made
    made.close()


def _python_source(block: Block) -> str:
    """The block, after the blocks it continues (same page)."""
    page = [b for b in BLOCKS if b.page == block.page and b.lang == "python"]
    i = page.index(block)
    parts = [block.body]
    while i + 1 < len(page) and page[i + 1].kind == "continues":
        i += 1
        parts.append(page[i].body)
    return "\n".join(parts)


def _commands(body: str) -> list[str]:
    """Shell lines of a block (comments and blank lines left out; ``\\`` joins)."""
    joined = body.replace("\\\n", " ")
    return [line for line in joined.splitlines()
            if line.strip() and not line.lstrip().startswith("#")]


@pytest.mark.parametrize("block", RUNNABLE, ids=lambda b: b.id)
def test_docs_example_runs_as_written(block: Block, env: Env) -> None:
    if block.kind == "sim":
        env.use_sim(block.note[len("sim"):].strip())
    else:
        env.stop_sim()
    if block.kind == "servers":
        for line in _commands(block.body):
            proc, log = env.start(line.split("  #")[0].strip())
            code = env.stop(proc)
            text = log.read_text()
            assert "Traceback" not in text and code in (0, 130, -2), f"{line}:\n{text}"
        return
    if block.lang == "python":
        done = env.run(["python", "-c", _python_source(block)])
        what = "the Python block"
    else:
        done = env.run(["bash", "-e", "-o", "pipefail", "-c", "\n".join(_commands(block.body))])
        what = "the shell block"
    output = done.stdout + done.stderr
    assert done.returncode == 0, f"{block.id}: {what} failed ({done.returncode}):\n{output}"
    assert "Traceback" not in output and "internal error" not in output, output
    shown = _printed(block)
    if shown is not None:
        why = _lines_match(shown.body.splitlines(), output.splitlines())
        assert not why, f"{shown.id} is not what {block.id} prints: {why}\n{output}"


def test_readme_version_sample_is_what_a_build_in_place_prints() -> None:
    """README's ``coolmuscle --version`` sample: the hot modules as many as
    ``_accel.MODULES`` and the mypyc pinned in pyproject.toml, in the words of
    ``_accel.describe`` for a build in place (what the scripts' editable install does)."""
    from coolmuscle import __version__, _accel
    pinned = re.search(r'"mypy==([0-9.]+)"', (ROOT / "pyproject.toml").read_text()).group(1)
    said = _accel.built({"SOURCES": {"x": [0, 0]}, "MYPYC": pinned})
    sample = next(b for b in BLOCKS if b.page.name == "README.md" and b.lang == "text"
                  and b.body.startswith("coolmuscle "))
    assert sample.body == (f"coolmuscle {__version__}\n"
                           f"hot modules: compiled ({len(_accel.MODULES)} modules {said})\n")

"""Captures of a "real" motor without hardware, for the twin's tests (docs/twin.md).

A hidden machine file stands in for the real machine: the identification session of
examples/twin/identify.py is played on a virtual motor with it, in virtual time, and
written in the capture format of ``coolmuscle capture`` (docs/twin.md "The capture
file") the way the relay would have seen it: each line sent stamped when its CR reached
the relay (a byte time before the motor had it) with the host's jitter, each line
received stamped when its last byte arrived (its wire time at the baud rate, plus the
relay's latency), and, with ``noise``, every polled value off by up to one unit of
noise before it is rounded (a real encoder and current sense).  Deterministic for a
seed.  ``python tests/twin_support.py`` writes examples/twin/session.cml.
"""

from __future__ import annotations

import importlib.util
import random
import re
import sys
from pathlib import Path
from types import ModuleType

from coolmuscle.chain.daisy import Chain
from coolmuscle.chain.machine import parse_machine
from coolmuscle.sim.kernel import NS_PER_S
from coolmuscle.tools.script.runner import TranscriptEntry, escape, parse_script, run_script
from coolmuscle.tools.twin.replay import exact_value
from coolmuscle.tools.twin.session import parse_poll

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "twin"

#: The machine behind the "real" motor: a heavier load (4e-5 kg·m² on a 0.45e-5 rotor),
#: more friction (0.03 N·m, the default is 0.004), a softer position loop and a stopper.
HIDDEN = {"inertia": 4.0e-5, "friction": 0.03, "kp": 220.0, "cw": 23500.0}
HIDDEN_TOML = """\
name = "hidden machine of the twin tests"
[[axis]]
motor = 1
[axis.load]
inertia = 4.0e-5
friction = 0.03
[axis.drive]
kp = 220.0
[axis.stoppers]
cw = 23500
"""
BAUD = 38400


def identify() -> ModuleType:
    """examples/twin/identify.py as a module (its ``plan``)."""
    spec = importlib.util.spec_from_file_location("twin_identify", EXAMPLE / "identify.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def session_plan(rounds: int = 1, push: bool = True) -> list[tuple[float, str]]:
    plan: list[tuple[float, str]] = identify().plan(0.01, rounds, 25000 if push else None)
    return plan


def capture_text(plan: list[tuple[float, str]], machine_toml: str | None = HIDDEN_TOML, *,
                 seed: int = 1, noise: bool = True, baud: int = BAUD,
                 tail: float = 0.5) -> str:
    """The capture a relay would have written of ``plan`` played on the hidden machine."""
    rng = random.Random(seed)
    machine = parse_machine(machine_toml, "hidden.toml") if machine_toml else None
    chain = Chain(machine=machine)
    origin = chain.kernel.now
    lines = []
    now = 0.0
    for at, text in plan:
        if at > now:
            lines.append(f"@wait {at - now:.6f}")
            now = at
        lines.append(text)
    lines.append(f"@wait {tail:.6f}")
    events: list[tuple[TranscriptEntry, bytes]] = []

    def on_entry(entry: TranscriptEntry) -> None:
        data = entry.data
        found = parse_poll(data.rstrip(b"\r\n").decode("latin-1")) if entry.direction == "<" \
            else None
        if found is not None and noise:
            assert found[1] in chain.motor_ids
            value = round(exact_value(chain, found[1], found[0]) + rng.uniform(-1.0, 1.0))
            data = f"{found[0]}.{found[1]}={value}\r\n".encode("ascii")
        events.append((entry, data))

    try:
        result = run_script(parse_script("\n".join(lines) + "\n"), chain, on_entry=on_entry)
    finally:
        chain.close()
    assert result.ok, result.summary()
    return _write(events, origin, rng, baud, round((now + tail) * NS_PER_S) + origin)


def _write(events: list[tuple[TranscriptEntry, bytes]], origin: int, rng: random.Random,
           baud: int, end: int) -> str:
    byte = 10 / baud
    sends = [e.time for e, _ in events if e.direction == ">"]
    out = [f"# coolmuscle capture: port=socket://127.0.0.1:5150 baud={baud} parity=none "
           "echo=on started=2026-12-03T10:00:00.000000Z",
           "# chain: motors=1 firmware=cm2"]
    vt = origin                      # virtual time of `run --check` at this point
    next_send = 0
    last = {">": 0.0, "<": 0.0}
    pending: list[str] = []          # lines sent whose echo is still to come
    for entry, data in events:
        if entry.time > vt:          # wait on to the next line sent (or the end)
            target = sends[next_send] if next_send < len(sends) else end
            out.append(f"@wait {(target - vt) / NS_PER_S:.6f}")
            vt = target
        at = (entry.time - origin) / NS_PER_S
        if entry.direction == ">":
            next_send += 1
            stamp = max(last[">"], at - byte + rng.gauss(0.0, 1e-4))
            last[">"] = stamp
            text = entry.data[:-1].decode("latin-1")
            out += [f"# t={stamp:.6f} >", text]
            pending.append(text)
            continue
        text = data.rstrip(b"\r\n").decode("latin-1")
        if text in pending:          # an echo: its last bytes (CR LF) follow the CR sent
            pending.remove(text)
            stamp = at + 2 * byte + abs(rng.gauss(0.0, 2e-4))
            out += [f"# t={max(stamp, last['<']):.6f} <", f"<< {escape(data)}"]
        else:                        # a reply or a report: its own wire time, latency
            stamp = at + len(data) * byte + 3e-4 + rng.expovariate(1 / 3e-4)
            out += [f"# t={max(stamp, last['<']):.6f} <", f"@until ^{re.escape(text)}$ 2.0",
                    f"<< {escape(data)}"]
        last["<"] = max(stamp, last["<"])
    if end > vt:
        out.append(f"@wait {(end - vt) / NS_PER_S:.6f}")
    sent = sum(1 for e, _ in events if e.direction == ">")
    out.append(f"# end: sent={sent} received={len(events) - sent} stopped=end-of-session")
    return "\n".join(out) + "\n"


def write_capture(folder: Path, name: str = "session.cml", *, seed: int = 1,
                  noise: bool = True, push: bool = True) -> Path:
    """A capture of the identification session on the hidden machine, in ``folder``."""
    path = folder / name
    path.write_text(capture_text(session_plan(push=push), seed=seed, noise=noise),
                    encoding="utf-8")
    return path


def write_hidden(folder: Path) -> Path:
    path = folder / "hidden.toml"
    path.write_text(HIDDEN_TOML, encoding="utf-8")
    return path


def main() -> None:
    """Write the example capture of docs/twin.md (and its hidden machine file)."""
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else EXAMPLE / "session.cml"
    target.write_text(capture_text(session_plan()), encoding="utf-8")
    print(f"wrote {target}")


if __name__ == "__main__":
    main()

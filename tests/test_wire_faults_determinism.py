"""Every wire fault a machine file schedules gives the same bytes on two runs
(docs/wire-faults.md "Determinism and cost"), and it acted.

The doors a ``coolmuscle run`` script reaches (the host line, the chain, Modbus RTU on
COM0 with ``@send`` frames) are run as scripts: the transcript (with its ``#`` notes of
what each fault did), the bytes received and the virtual times the host read them must
be equal bit for bit, and differ from the same script's run without the fault.  The
network doors (Modbus TCP, the CM1's EtherNet/IP) take their timing from the peer; the
model's part of the Modbus TCP door (which request a fault hits, what it answers) is run
twice through the device API with the same requests.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from coolmuscle.chain.daisy import Chain
from coolmuscle.tools.script.runner import run_script
from modbus_support import frame

QUERIES = "K23.1=0\n" + "".join(f"?96.{n}\n?99.{n}\nP1.{n}={i}\nP1.{n}\n@wait 0.05\n"
                                 for i in range(12) for n in (1, 2, 3))
#: FC03 P0 of station 1 (K78=0: register 200), FC16 P0 = 42, FC03 P1 (5.6.8).
FRAMES = [frame("01 03 00 C8 00 02"), frame("01 10 00 C8 00 02 04 00 00 00 2A"),
          frame("01 03 00 CA 00 02")]
MODBUS = "".join("@send " + "".join(f"\\x{b:02x}" for b in f) + "\n@wait 0.05\n"
                 for _ in range(8) for f in FRAMES)
RTU_MODE = "[[axis]]\nparams = { K81 = 1 }\n"      # COM0 speaks Modbus RTU (K81, 5.6)

PER_MESSAGE = "probability = 0.4\nseed = 11\n"
CASES = {
    "host-line drop": ("host-line", "drop", PER_MESSAGE, ""),
    "host-line garble": ("host-line", "garble", PER_MESSAGE, ""),
    "host-line delay": ("host-line", "delay", PER_MESSAGE + "ms = 70\n", ""),
    "host-line split": ("host-line", "split", PER_MESSAGE + "pieces = 3\ngap_ms = 3\n", ""),
    "host-line duplicate": ("host-line", "duplicate", PER_MESSAGE, ""),
    "host-line latency": ("host-line", "latency", "at = 0.3\nuntil = 1.2\n", ""),
    "host-line dead": ("host-line", "dead", "at = 0.4\nuntil = 0.9\n", ""),
    "chain power_off": ("chain", "power_off", "motor = 2\nat = 0.3\nuntil = 1.1\n", ""),
    "chain link_break": ("chain", "link_break", "motor = 1\nat = 0.3\nuntil = 1.1\n", ""),
    "modbus-rtu no_reply": ("modbus-rtu", "no_reply", PER_MESSAGE, RTU_MODE),
    "modbus-rtu late": ("modbus-rtu", "late", PER_MESSAGE + "ms = 80\n", RTU_MODE),
    "modbus-rtu exception": ("modbus-rtu", "exception", PER_MESSAGE + "code = 6\n",
                             RTU_MODE),
    "modbus-rtu bad_crc": ("modbus-rtu", "bad_crc", PER_MESSAGE, RTU_MODE),
    "modbus-rtu wrong_slave": ("modbus-rtu", "wrong_slave", PER_MESSAGE, RTU_MODE),
    "modbus-rtu silence gap": ("modbus-rtu", "silence", PER_MESSAGE, RTU_MODE),
    "modbus-rtu silence merge": ("modbus-rtu", "silence", PER_MESSAGE + 'mode = "merge"\n',
                                 RTU_MODE),
}


def _run(script: str, machine: Path) -> tuple[str, bytes, list[tuple[int, bytes]]]:
    """The transcript, the bytes received and each piece the host read with its
    virtual time (a Modbus frame has no line end to time it by in the transcript)."""
    chain = Chain(motors=3, machine=machine)
    pieces: list[tuple[int, bytes]] = []
    chain.host_line.add_listener(lambda data: pieces.append((chain.kernel.now, data)))
    try:
        result = run_script(script, chain)
    finally:
        chain.close()
    return result.format(), result.received, pieces


@pytest.mark.parametrize("case", sorted(CASES))
def test_each_machine_file_fault_gives_the_same_transcript_twice(tmp_path, case):
    door, kind, table, before = CASES[case]
    script = MODBUS if before else QUERIES
    clean = tmp_path / "clean.toml"
    clean.write_text(before)
    faulty = tmp_path / "faulty.toml"
    faulty.write_text(f'{before}\n[[wire.fault]]\ndoor = "{door}"\nkind = "{kind}"\n{table}')
    first, second = _run(script, faulty), _run(script, faulty)
    assert first == second
    assert f"{door} {kind}:" in first[0]                    # it acted, and said so
    without = _run(script, clean)
    assert "# wire" not in without[0]
    assert first[2] != without[2]                # the host read otherwise, or at other times


def _model_run(door: str, kind: str, params: dict[str, object]
               ) -> tuple[list[bytes | None], list[tuple[int, str, str]]]:
    chain = Chain()
    events: list[tuple[int, str, str]] = []
    chain.subscribe(lambda e: events.append((e.time, e.kind, e.text)))
    chain.inject_wire_fault(door, kind, probability=0.4, seed=5, **params)
    answers: list[bytes | None] = []
    for i in range(60):
        pdu = bytes.fromhex("03 00 C8 00 02") if i % 2 else \
            bytes.fromhex("10 00 C8 00 02 04 00 00") + i.to_bytes(2, "big")
        answers.append(chain.modbus_request(1, pdu, tcp=True))
        chain.kernel.advance(0.01)
    chain.close()
    return answers, events


@pytest.mark.parametrize("kind, params", [("no_reply", {}), ("exception", {"code": 4})])
def test_modbus_tcp_faults_hit_the_same_requests_twice(kind, params):
    first, second = _model_run("modbus-tcp", kind, params), \
        _model_run("modbus-tcp", kind, params)
    assert first == second
    answers, events = first
    hit = sum(1 for e in events if e[1] == "wire")
    served = sum(1 for a in answers if a is not None and a[0] in (0x03, 0x10))
    assert 10 < hit < 50 and hit + served == 60          # p = 0.4 of 60, the rest served

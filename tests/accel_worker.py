"""Run scripts and csp streams and print a digest of everything they produce.

Run by tests/test_accel.py twice, once with the compiled hot modules and once with
``COOLMUSCLE_PURE=1`` (coolmuscle/_accel.py): the two outputs must be byte-identical.
For each script (examples/*.cml, tests/transcripts/*.cml): the bytes the motors send,
and a 1 ms trace of every motor (positions, speeds, torques, status, I/O) as CSV;
then a 4-axis csp stream (Chain.target_stream) sampled every cycle, the EtherCAT
bridge's own cycle in csp (its TxPDO image every cycle), and a PTP bank looping on 15
motors.  One line per item: name, length and SHA-256 of its bytes.

``accel_worker.py ROOT --sample`` runs a few of them, shorter: a guide example, three
golden transcripts (motion, a program bank, interpolation) each with its trace, 500 csp
cycles and a 15-motor bank for 20 s (tests/test_packaging.py, on an installed wheel).
"""

from __future__ import annotations

import hashlib
import json
import math
import sys
import tempfile
from pathlib import Path

import coolmuscle._accel as accel
from coolmuscle.chain.daisy import Chain
from coolmuscle.tools.cli.run import header_defaults, make_chain
from coolmuscle.tools.script.runner import run_script


def digest(data: bytes) -> str:
    return f"{len(data)} {hashlib.sha256(data).hexdigest()}"


def script_item(path: Path, work: Path) -> str:
    motors, firmware, machine = header_defaults(path, None, None, None)
    chain = make_chain(Chain, motors, firmware, None, False, machine)
    trace = work / (path.stem + ".csv")
    try:
        result = run_script(path, chain, until=None, trace=trace, trace_step=0.001)
        out = result.received + b"\n--\n" + result.format().encode()
    finally:
        chain.close()
    return f"{path.name}: out {digest(out)} trace {digest(trace.read_bytes())}"


def stream_item(cycles: int) -> str:
    chain = Chain(motors=4)
    streams = [chain.target_stream(n) for n in range(1, 5)]
    rows = []
    for i in range(cycles):
        for n, stream in enumerate(streams, 1):
            half = 2000.0 + 50.0 * n
            stream.push(round(half - half * math.cos(2.0 * math.pi * i / 4000.0)))
        chain.kernel.advance(1_000_000)
        rows.append(",".join(f"{m.axis.raw_actual()!r}:{m.axis.position_error()!r}"
                             for m in chain.motors.values()))
    return f"csp stream: {digest(chr(10).join(rows).encode())}"


def bridge_item(cycles: int) -> str:
    """The bridge (EB02) in csp: 6.1.2's enable, a triangle of targets, a disable."""
    import struct

    from coolmuscle.frontends.ethercat.bridge.app import BridgeApp
    chain = Chain(motors=4)
    app = BridgeApp(chain, "EB02")
    od = app.dictionary
    app.start_cycles()
    images: list[bytes] = []

    def ms(cw: int, target: int) -> None:
        od.unpack_outputs(struct.pack("<" + "Hi" * 4, *([cw, target] * 4)))
        chain.kernel.advance(1_000_000)
        images.append(od.pack_inputs())

    for cw in (0x06, 0x07, 0x0F):
        for _ in range(5):
            ms(cw, 0)
    for i in range(cycles):
        phase = i % 2000
        ms(0x0F, 3 * phase if phase < 1000 else 6000 - 3 * phase)
    for _ in range(50):
        ms(0x07, 0)
    return f"bridge csp: {digest(b''.join(images))}"


def bank_item(seconds: int) -> str:
    chain = Chain(motors=15)
    got: list[str] = []
    chain.subscribe(lambda e: got.append(f"{e.time} {e.text}"))
    for n in range(1, 16):
        for line in (f"S1.{n}={100 + n}, A1.{n}=100, P1.{n}=10000, P2.{n}=0", f"B1.{n}",
                     "X0", f"S1.{n}, A1.{n}, P1.{n}", f"P2.{n}", "X-", "END"):
            chain.execute(line)
    for n in range(1, 16):
        chain.execute(f"[1.{n}")
    chain.kernel.run(until=seconds * 1_000_000_000)
    tail = ",".join(repr(m.axis.raw_actual()) for m in chain.motors.values())
    return f"15-motor bank: {digest(chr(10).join(got).encode() + tail.encode())}"


#: The scripts of ``--sample``.
SAMPLE = ("examples/2.1-operation.cml", "tests/transcripts/4.1.3-acceleration-deceleration.cml",
          "tests/transcripts/2.2-operation-example.cml", "tests/transcripts/4.4.3-linear.cml")


def main(root: str, sample: bool = False) -> None:
    base = Path(root)
    if sample:
        scripts = [base / name for name in SAMPLE]
    else:
        scripts = (sorted(base.glob("examples/*.cml"))
                   + sorted(base.glob("tests/transcripts/*.cml")))
    print(json.dumps({"compiled": accel.active(), "reason": accel.state["reason"]}))
    with tempfile.TemporaryDirectory() as work:
        for path in scripts:
            print(script_item(path, Path(work)))
    cycles, seconds = (500, 20) if sample else (3000, 120)
    print(stream_item(cycles))
    print(bridge_item(cycles))
    print(bank_item(seconds))


if __name__ == "__main__":
    main(sys.argv[1], sample=sys.argv[2:] == ["--sample"])

"""The compiled hot modules do not leak: no ``bytes + bytes`` in them, and the compiled
build's memory stays flat over a million lines the motor sends and a million csp cycles.

mypyc 1.19 compiles ``bytes + bytes`` to a call that it believes takes over the left
operand, which the call does not, so that operand is never freed (docs/performance.md
"Compiled hot modules": 48 bytes a line the motor sent).  The same code as source does
not leak, so the memory tests run only when the compiled modules are the ones imported
(``./scripts/test`` compiles them first); the lint reads the sources and always runs.

Memory is counted as the interpreter's allocated blocks (``sys.getallocatedblocks``):
a leaked object is one block, and nothing is traced, so a million calls stay fast.
"""

from __future__ import annotations

import ast
import gc
import struct
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from coolmuscle import _accel
from coolmuscle.chain import Chain

SRC = Path(_accel.PACKAGE_DIR)

compiled = pytest.mark.skipif(
    not _accel.active(),
    reason=f"the compiled modules are not in use ({_accel.describe()}): "
           "python -m coolmuscle.tools.accel build")


# -- the lint: no bytes concatenation in a compiled module --------------------------------

def _bytes_names(tree: ast.AST) -> set[str]:
    """Names and attributes annotated ``bytes`` anywhere in ``tree`` (parameters,
    annotated assignments, class fields)."""
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.arg) and _is_bytes(node.annotation):
            names.add(node.arg)
        elif isinstance(node, ast.AnnAssign) and _is_bytes(node.annotation):
            target = node.target
            names.add(target.attr if isinstance(target, ast.Attribute) else
                      target.id if isinstance(target, ast.Name) else "")
    return names - {""}


def _is_bytes(annotation: ast.expr | None) -> bool:
    return isinstance(annotation, ast.Name) and annotation.id == "bytes" or (
        isinstance(annotation, ast.Constant) and annotation.value == "bytes")


def _is_bytes_expr(node: ast.expr, names: set[str]) -> bool:
    """``node`` is bytes as far as its text tells: a bytes literal, ``x.encode(...)``,
    ``bytes(...)``, a name or attribute annotated ``bytes``, or a sum of one."""
    if isinstance(node, ast.Constant):
        return isinstance(node.value, bytes)
    if isinstance(node, ast.Call):
        func = node.func
        return (isinstance(func, ast.Attribute) and func.attr == "encode"
                or isinstance(func, ast.Name) and func.id == "bytes")
    if isinstance(node, ast.Name):
        return node.id in names
    if isinstance(node, ast.Attribute):
        return node.attr in names
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
        return _is_bytes_expr(node.left, names) or _is_bytes_expr(node.right, names)
    return False


def _bytearray_names(tree: ast.AST) -> set[str]:
    """Names and attributes that hold a ``bytearray`` (``x = bytearray(...)``,
    ``self.x = bytearray()``, annotated ``bytearray``): ``+=`` onto one is not mypyc's
    bytes concatenation (it treats a bytearray as an object) and does not leak."""
    names: set[str] = set()
    for node in ast.walk(tree):
        targets: list[ast.expr] = []
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Call) and \
                isinstance(node.value.func, ast.Name) and node.value.func.id == "bytearray":
            targets = list(node.targets)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.annotation, ast.Name) \
                and node.annotation.id == "bytearray":
            targets = [node.target]
        names |= {_name(target) for target in targets}
    return names - {""}


def _name(node: ast.expr) -> str:
    return node.attr if isinstance(node, ast.Attribute) else \
        node.id if isinstance(node, ast.Name) else ""


def bytes_additions(sources: dict[str, str]) -> Iterator[str]:
    """``path:line: text`` of every ``+`` or ``+=`` on bytes in ``sources`` (path ->
    source text); ``+=`` onto a bytearray is not one."""
    trees = {path: ast.parse(text) for path, text in sources.items()}
    names = set().union(*(_bytes_names(tree) for tree in trees.values()))
    for path, tree in trees.items():
        arrays = _bytearray_names(tree)
        for node in sorted(ast.walk(tree), key=lambda n: getattr(n, "lineno", 0)):
            if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
                operands = (node.left, node.right)
            elif isinstance(node, ast.AugAssign) and isinstance(node.op, ast.Add):
                if _name(node.target) in arrays:
                    continue
                operands = (node.target, node.value)
            else:
                continue
            if any(_is_bytes_expr(operand, names) for operand in operands):
                yield f"{path}:{node.lineno}: {ast.unparse(node)}"


def test_the_lint_finds_the_leaking_shapes() -> None:
    """The lint itself: each shape mypyc compiles to its leaking concatenation, and not
    ``+=`` onto a bytearray."""
    source = '''
class Settings:
    delimiter: bytes

def send(text: str, settings: Settings, tail: bytes) -> None:
    a = text.encode("latin-1") + settings.delimiter
    b = bytes(buf) + tail
    c = held.delimiter + b"\\n"
    d = tail + a
    out = bytearray()
    out += b"\\x00"
    tail += b"\\x00"
    e = b"".join((a, tail))
    f = "text" + str(a)
'''
    found = [line.split(": ", 1)[1] for line in bytes_additions({"m.py": source})]
    assert found == ["text.encode('latin-1') + settings.delimiter", "bytes(buf) + tail",
                     "held.delimiter + b'\\n'", "tail + a", "tail += b'\\x00'"]


def test_no_compiled_module_adds_bytes() -> None:
    """Every bytes concatenation in a compiled module is written ``b"".join((a, b))``."""
    sources = {rel: (SRC / rel).read_text(encoding="utf-8")
               for rel in map(_accel.source_relpath, _accel.MODULES)}
    assert list(bytes_additions(sources)) == []


# -- the compiled build's memory -----------------------------------------------------------

def _growth(run: Callable[[int], None], n: int, settle: Callable[[], None]) -> int:
    """Allocated blocks ``run(n)`` leaves behind, after a warm-up and ``settle()``."""
    run(2000)
    settle()
    gc.collect()
    before = sys.getallocatedblocks()
    run(n)
    settle()
    gc.collect()
    return sys.getallocatedblocks() - before


@compiled
def test_a_million_lines_sent_leave_memory_flat() -> None:
    """The motor's lines (``HostLine.send_line``), lines typed by two hosts at once (the
    echo at each line end) and ``?96.1`` polls: before, one block (48 B) a line sent."""
    chain = Chain(motors=1)
    line = chain.host_line
    heard = [0]
    line.add_listener(lambda data: heard.__setitem__(0, heard[0] + len(data)))

    def send(n: int) -> None:
        for _ in range(n):
            line.send_line("Px.1=1000")

    assert _growth(send, 1_000_000, lambda: None) < 1000
    line.open_source("a")
    line.open_source("b")

    def shared(n: int) -> None:
        for _ in range(n // 2):
            line.feed(b"?9", source="a")     # cut by b's whole line: a's echo again whole
            line.feed(b"?96.1\r", source="b")
            line.feed(b"6.1\r", source="a")

    assert _growth(shared, 100_000, lambda: None) < 1000
    assert heard[0] > 1_000_000 * len(b"Px.1=1000\r\n")


@compiled
@pytest.mark.slow
@pytest.mark.timeout(900)
def test_a_million_csp_cycles_leave_memory_flat() -> None:
    """One axis of the EtherCAT bridge following a triangle in csp (a new target each
    1 ms cycle), a million cycles: the bridge's compiled modules, the motor's solve and
    its reports.  The chain's motion memos and the CML mailbox are bounded; they are
    emptied before each count so only what a cycle leaves behind is counted."""
    from coolmuscle.frontends.ethercat.bridge.app import BridgeApp

    chain = Chain(None, 1, firmware="cm2")
    kernel = chain.kernel
    app = BridgeApp(chain, "EB02")
    od = app.dictionary

    def frame(controlword: int, target: int) -> None:
        data = struct.pack("<" + "Hi" * 4, *([controlword, target] * 4))
        od.unpack_outputs(data)
        app.outputs(data)

    app.start_cycles(1_000_000)
    for controlword in (0x06, 0x07, 0x0F):                 # to Operation enabled (6.1.2)
        frame(controlword, 0)
        kernel.run(until=kernel.now + 5_000_000)
    cycle = [0]

    def follow(n: int) -> None:
        for _ in range(n):
            phase = cycle[0] % 8000                       # +/-4,000 pulses, 2 a cycle
            cycle[0] += 1
            frame(0x0F, 2 * phase if phase < 2000 else 8000 - 2 * phase if phase < 6000
                  else 2 * phase - 16000)
            kernel.run(until=kernel.now + 1_000_000)

    def settle() -> None:
        chain.motion_memos.clear()
        for mailbox in app.drive.mailboxes.values():
            mailbox.clear()

    assert _growth(follow, 1_000_000, settle) < 1000
    assert abs(chain.snapshot(1).position) < 4100

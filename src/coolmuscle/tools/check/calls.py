"""``coolmuscle check``: the rules on calls and jumps between banks.

cml-users-guide.txt 2.2.2 "C": "C command can not be used to call the other ID's
Program Bank.  Program Bank where C command executes cannot be called again.  The
maximum layer (nesting) should be under 10"; "J" jumps and does not come back; 2.2.3
"CL"/"JL" the same for ladder banks; 4.2.5 "The maximum nesting level ... is up to 10".

* ``missing-bank``: a call or jump to a bank the file does not define (the motor
  answers error05 / error06 when it runs);
* ``cross-motor-call``: a call or jump naming another motor ID;
* ``recursion``: a bank reachable again from itself through calls (``C``/``CL``);
  a loop through jumps alone is allowed (it is how banks repeat);
* ``nesting``: more than 10 banks deep through calls (a jump stays at its level).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ...client.program import BankBlock, ProgramFile, SourceLine
from ...cml import ast

if TYPE_CHECKING:
    from .report import CheckReport

__all__ = ["check_calls"]

BankKey = tuple[bool, int, int]       # (ladder, number, motor)
Edge = tuple[str, BankKey, SourceLine]  # ("call" | "jump", target, where)

MAX_DEPTH = 10


def _edges(block: BankBlock, defined: dict[BankKey, BankBlock],
           report: CheckReport, rt3: bool) -> list[Edge]:
    from .tree import column as _column
    from .tree import flat as _flat
    edges: list[Edge] = []
    for line in block.body:
        for statement in line.statements:
            for each in _flat(statement):
                if not isinstance(each, ast.Call):
                    continue
                # RT3 calls logic banks with C#/J# too (its 1.1 examples; fidelity.md)
                ladder = each.kind in ("CL", "JL") or (rt3 and block.ladder)
                motor = each.motor or block.motor_id
                text = f"{each.kind}{each.index}"
                column = _column(line.raw, text)
                if ladder != block.ladder:
                    kind = "ladder" if block.ladder else "program"
                    report.add(line, "not-in-bank", f"{text} cannot be used in a {kind} bank",
                               column=column, motor_error=3)
                    continue
                if motor != block.motor_id:
                    report.add(line, "cross-motor-call", f"{text}.{motor} names motor "
                               f"{motor}'s bank from {block.label} (2.2.2: not allowed)",
                               column=column)
                    continue
                target = (ladder, each.index, motor)
                if target not in defined:
                    kind = "ladder" if ladder else "program"
                    report.add(line, "missing-bank", f"{text} goes to {kind} bank "
                               f"{each.index} of motor {motor}, which this file does not "
                               "define", column=column, motor_error=6 if ladder else 5)
                    continue
                edges.append(("call" if each.kind in ("C", "CL") else "jump", target, line))
    return edges


def check_calls(program: ProgramFile, defined: dict[BankKey, BankBlock],
                report: CheckReport, rt3: bool = False) -> None:
    """Add the call/jump diagnostics of ``program`` to ``report`` (``rt3``: the RT3 and
    CM1 bank rules, where a logic bank calls with ``C#`` and ``J#`` as well)."""
    graph: dict[BankKey, list[Edge]] = {}
    for block in program.banks:
        key = (block.ladder, block.number, block.motor_id)
        if defined.get(key) is block:
            graph[key] = _edges(block, defined, report, rt3)
    _recursion(graph, report)
    _depth(graph, report)


def _recursion(graph: dict[BankKey, list[Edge]], report: CheckReport) -> None:
    """A call edge that closes a cycle of calls and jumps containing a call."""
    reported: set[int] = set()
    for start in graph:
        stack: list[tuple[BankKey, bool]] = [(start, False)]
        seen: set[tuple[BankKey, bool]] = set()
        while stack:
            node, called = stack.pop()
            for kind, target, line in graph.get(node, []):
                through_call = called or kind == "call"
                if target == start and through_call:
                    if line.number not in reported and kind == "call":
                        reported.add(line.number)
                        label = f"{'L' if start[0] else 'B'}{start[1]}.{start[2]}"
                        report.add(line, "recursion", f"{label} is called again from "
                                   "itself (2.2.2 C: a calling bank cannot be called again)")
                    continue
                state = (target, through_call)
                if state not in seen:
                    seen.add(state)
                    stack.append(state)


def _depth(graph: dict[BankKey, list[Edge]], report: CheckReport) -> None:
    """Longest chain of calls (banks deep); cycles are left to ``recursion``."""
    memo: dict[BankKey, int] = {}

    def depth(node: BankKey, path: frozenset[BankKey]) -> int:
        if node in memo:
            return memo[node]
        best = 1
        for kind, target, _line in graph.get(node, []):
            if target in path:
                continue
            below = depth(target, path | {node})
            best = max(best, below + 1 if kind == "call" else below)
        memo[node] = best
        return best

    for node in graph:
        level = depth(node, frozenset())
        if level > MAX_DEPTH:
            first = next((line for kind, _t, line in graph[node] if kind == "call"), None)
            if first is not None:
                label = f"{'L' if node[0] else 'B'}{node[1]}.{node[2]}"
                report.add(first, "nesting", f"calls from {label} nest {level} banks deep "
                           f"(at most {MAX_DEPTH}, 2.2.2 C)")
            break

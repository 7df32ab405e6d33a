"""The import graph of docs/architecture.md, enforced (grimp, import-linter's engine).

- layers: tools > client > frontends > chain > device > motor > cml > sim > errors; a
  module imports only from its own layer or below (type-only imports included);
- no import circle between modules, type-only imports counted too: the parts of a motor
  see it through the ``motor.core.MotorCore`` protocol, never the façade ``motor.motor``;
- rule 1: nothing under motor/, chain/, device/, cml/ (nor the kernel) imports time,
  asyncio, socket or threading: virtual time only.
"""

from __future__ import annotations

import sys
from functools import lru_cache

import grimp
import pytest

LAYERS = ("coolmuscle.tools", "coolmuscle.client", "coolmuscle.frontends", "coolmuscle.chain",
          "coolmuscle.device", "coolmuscle.motor", "coolmuscle.cml", "coolmuscle.sim",
          "coolmuscle.errors")
#: The one documented exception: an AlarmError decodes its Ux with the motor's status flags.
ALLOWED_UPWARD = {("coolmuscle.errors", "coolmuscle.motor.status")}
VIRTUAL_TIME = ("coolmuscle.motor", "coolmuscle.chain", "coolmuscle.device", "coolmuscle.cml",
                "coolmuscle.sim.kernel")
CLOCKS = frozenset({"time", "asyncio", "socket", "threading"})


@lru_cache(maxsize=None)
def graph(type_checking: bool, external: bool = False) -> grimp.ImportGraph:
    return grimp.build_graph("coolmuscle", exclude_type_checking_imports=not type_checking,
                             include_external_packages=external, cache_dir=None)


def circles(g: grimp.ImportGraph) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10_000))
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in g.find_modules_directly_imported_by(v):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for module in sorted(g.modules):
        if module not in index:
            visit(module)
    return found


@pytest.mark.parametrize("type_checking", [False, True], ids=["runtime", "with-type-only"])
def test_layers_import_only_downward(type_checking: bool) -> None:
    illegal = []
    for dep in graph(type_checking).find_illegal_dependencies_for_layers(layers=LAYERS):
        for route in dep.routes:
            pairs = {(h, t) for h in route.heads for t in route.tails}
            if not pairs <= ALLOWED_UPWARD:
                illegal.append((dep.importer, dep.imported, sorted(pairs)))
    assert illegal == []


@pytest.mark.parametrize("type_checking", [False, True], ids=["runtime", "with-type-only"])
def test_no_import_circle(type_checking: bool) -> None:
    assert circles(graph(type_checking)) == []


def test_circles_finds_a_circle() -> None:
    """The check bites: the façade and a part that imported it back would be one."""
    g = graph.__wrapped__(True)             # a graph of its own, not the cached one
    g.add_import(importer="coolmuscle.motor.supervision.supervisor",
                 imported="coolmuscle.motor.motor")
    assert circles(g) == [["coolmuscle.motor.motor", "coolmuscle.motor.supervision.supervisor"]]


def test_the_facade_has_every_member_the_parts_see() -> None:
    """``MotorCore`` (what programs, signals and supervision use) is met by ``Motor``."""
    from coolmuscle.chain import Chain
    from coolmuscle.motor import core

    motor = Chain(motors=1).motor(1)
    for protocol, part in ((core.MotorCore, motor), (core.ProgramRunner, motor.program),
                           (core.BankRunner, motor.ladder), (core.BankRunner, motor.logic_motion),
                           (core.InputFunctionsView, motor.inputs),
                           (core.OriginSearchView, motor.origin)):
        members = [n for n in dir(protocol) if not n.startswith("_")] + list(
            getattr(protocol, "__annotations__", {}))
        assert members
        missing = [n for n in members if not hasattr(part, n)]
        assert missing == [], (protocol.__name__, missing)


def test_every_layer_exists_and_the_graph_is_whole() -> None:
    modules = graph(False).modules
    for layer in LAYERS:
        assert layer in modules, layer
    assert len(modules) > 100   # the graph was really built


def test_the_model_reads_no_clock_and_opens_no_threads_or_sockets() -> None:
    """docs/architecture.md rule 1: time is Kernel.now; delays go through Kernel.schedule."""
    g = graph(True, external=True)
    offenders = {}
    for module in sorted(g.modules):
        if module.startswith(VIRTUAL_TIME):
            bad = g.find_modules_directly_imported_by(module) & CLOCKS
            if bad:
                offenders[module] = sorted(bad)
    assert offenders == {}
    assert "time" in g.find_modules_directly_imported_by("coolmuscle.sim.realtime")  # test bites

"""The import graph of docs/architecture.md, enforced (grimp, import-linter's engine).

- layers: testing > tools > client > frontends > chain > device > motor > cml > sim >
  errors; a
  module imports only from its own layer or below (type-only imports included);
- rooms: inside tools/, frontends/, chain/ and motor/ the sub-packages (and the modules
  beside them) are ordered too (``ROOMS``): a room imports only rooms below it, the rooms
  of one line not each other, and every module has its room;
- plug-ins named by a string (``"module:attr"`` in a registry such as the transports',
  pyproject.toml's entry points) count as imports by the module that loads them: they
  obey the layers and the rooms, and name a module and attribute that exist;
- no import circle between modules, type-only imports counted too: the parts of a motor
  see it through the ``motor.core.MotorCore`` protocol, never the façade ``motor.motor``;
- rule 1: nothing under motor/, chain/, device/, cml/ (nor the kernel) imports time,
  asyncio, socket or threading: virtual time only.
"""

from __future__ import annotations

import ast
import copy
import importlib.util
import re
import sys
import tomllib
from functools import cache
from pathlib import Path

import grimp
import pytest

LAYERS = ("coolmuscle.testing", "coolmuscle.tools", "coolmuscle.client", "coolmuscle.frontends",
          "coolmuscle.chain",
          "coolmuscle.device", "coolmuscle.motor", "coolmuscle.cml", "coolmuscle.sim",
          "coolmuscle.errors")
#: The one documented exception: an AlarmError decodes its Ux with the motor's status flags.
ALLOWED_UPWARD = {("coolmuscle.errors", "coolmuscle.motor.status")}
VIRTUAL_TIME = ("coolmuscle.motor", "coolmuscle.chain", "coolmuscle.device", "coolmuscle.cml",
                "coolmuscle.sim.kernel")
CLOCKS = frozenset({"time", "asyncio", "socket", "threading"})

#: The rooms of a layer, top to bottom: a room imports only the rooms of the lines below
#: its own, never a room of its own line.  A room is a sub-package or a module, named
#: below its layer; ``name.__init__`` is a package's own module alone.  A module is in the
#: room of the longest name it starts with.
ROOMS: dict[str, tuple[tuple[str, ...], ...]] = {
    "coolmuscle.testing": (
        ("plugin",),                     # the pytest plug-in: the fixtures
        ("rig",),                        # a chain under test
        ("expect", "coverage", "lab"),   # assertions, bank coverage, the EtherCAT lab
        ("banks", "served", "ledger"),   # bank files, sims as processes, what was started
    ),
    "coolmuscle.tools": (
        ("cli.entry",),                  # the command's first code
        ("cli.app",),                    # the typer application: every sub-command
        ("cli.exits",),                  # one-line errors and exit codes of both paths
        ("web",),                        # the page: a motor's desk and its twin
        ("batch", "capture", "desk", "twin", "cli"),   # sub-commands; cli: the rest
        ("cli.host_commands",),          # check, upload, term
        ("cli.run", "term"),             # what run does; the terminal and its upload
        ("script",),                     # scripts, transcripts
        ("check", "trace", "accel"),     # the linter, traces and plots, compiled modules
        ("cli.ports",),                  # PORT as every command takes it
        ("cli.usage", "cli.stopsignals", "cli.version",    # what every command shares,
         "ci"),                                             # and the CI formats they write
    ),
    "coolmuscle.frontends": (
        ("transports.__init__",),        # the registry: names every front end
        ("enip", "ethercat", "urlhandler"),
        ("transports",),                 # byte pipes, Port and its Lanes, the service
    ),
    "coolmuscle.chain": (
        ("daisy",),                      # Chain: the device API
        ("bus", "firmware_modbus", "machine", "banklines", "power"),
        ("links",),
    ),
    "coolmuscle.motor": (
        ("motor",),                      # the façade builds every part
        ("programs", "supervision"),
        ("signals",),
        ("core",),                       # what the parts see of the motor
        ("motion",),
        ("state",),
        ("context", "status"),
    ),
}
#: ``MotorCore`` types two members with the parts' own classes (``DigitalIO``,
#: ``Thermal``): compiled, the parts call their methods directly (a protocol would not).
ALLOWED_INSIDE = {("coolmuscle.motor.core", "coolmuscle.motor.signals.io"),
                  ("coolmuscle.motor.core", "coolmuscle.motor.supervision.thermal")}

#: Entry-point groups and the module that loads each (pyproject.toml).
ENTRY_POINT_LOADERS: dict[str, str | None] = {
    "coolmuscle.transports": "coolmuscle.frontends.transports",
    "pytest11": None,                   # pytest loads it, from outside the package
}
#: Groups whose entry points the installer's scripts load, from outside the package.
SCRIPT_GROUPS = ("scripts", "gui-scripts")
PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"
_PLUGIN = re.compile(r"(coolmuscle(?:\.\w+)+):(\w+(?:\.\w+)*)")


@cache
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


def illegal_layer_imports(g: grimp.ImportGraph) -> list[tuple[str, str, list[tuple[str, str]]]]:
    illegal = []
    for dep in g.find_illegal_dependencies_for_layers(layers=LAYERS):
        for route in dep.routes:
            pairs = {(h, t) for h in route.heads for t in route.tails}
            if not pairs <= ALLOWED_UPWARD:
                illegal.append((dep.importer, dep.imported, sorted(pairs)))
    return illegal


@pytest.mark.parametrize("type_checking", [False, True], ids=["runtime", "with-type-only"])
def test_layers_import_only_downward(type_checking: bool) -> None:
    """Plug-ins named by a string count: a registry entry is an import by its loader."""
    assert illegal_layer_imports(plugged(type_checking)) == []


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


# -- rooms inside a layer ------------------------------------------------------------------

def _relative(layer: str, module: str, g: grimp.ImportGraph) -> str:
    """``module`` named below ``layer``; a package's own module ends in ``.__init__``."""
    name = module[len(layer) + 1:]
    if g.find_children(module):
        name += ".__init__"
    return name


def room_of(layer: str, module: str, g: grimp.ImportGraph) -> str | None:
    """The room of ``module`` (the longest room name it starts with), or None."""
    name = _relative(layer, module, g)
    rooms = [room for line in ROOMS[layer] for room in line
             if name == room or name.startswith(room + ".")]
    return max(rooms, key=len, default=None)


def _line_of(layer: str) -> dict[str, int]:
    return {room: depth for depth, line in enumerate(ROOMS[layer]) for room in line}


def rooms_against_the_order(g: grimp.ImportGraph) -> list[tuple[str, str, str]]:
    """Imports from a room to a room of its own line or above (or to the layer's own
    module, which stands above them all), as (importer, imported, rooms)."""
    found = []
    for layer in ROOMS:
        line = _line_of(layer)
        for importer in sorted(m for m in g.modules if m.startswith(layer + ".")):
            here = room_of(layer, importer, g)
            for imported in sorted(g.find_modules_directly_imported_by(importer)):
                if imported == layer:
                    found.append((importer, imported, f"{here} -> the layer's own module"))
                    continue
                if not imported.startswith(layer + ".") or (importer, imported) in ALLOWED_INSIDE:
                    continue
                there = room_of(layer, imported, g)
                if here != there and (here is None or there is None
                                      or line[here] >= line[there]):
                    found.append((importer, imported, f"{here} -> {there}"))
    return found


@pytest.mark.parametrize("type_checking", [False, True], ids=["runtime", "with-type-only"])
def test_rooms_import_only_the_rooms_below_them(type_checking: bool) -> None:
    """docs/architecture.md "The layout in one picture": no lower sub-package imports a
    higher one inside a layer; string-named plug-ins count."""
    assert rooms_against_the_order(plugged(type_checking)) == []


def test_every_module_has_its_room_and_every_room_its_modules() -> None:
    g = graph(True)
    for layer, lines in ROOMS.items():
        rooms = [room for line in lines for room in line]
        assert len(rooms) == len(set(rooms)), layer
        modules = [m for m in g.modules if m.startswith(layer + ".")]
        assert [m for m in modules if room_of(layer, m, g) is None] == [], layer
        used = {room_of(layer, m, g) for m in modules}
        assert [room for room in rooms if room not in used] == [], layer


def test_the_room_order_bites() -> None:
    """The upward import ``motor/state/firmware.py`` once had (the output functions of
    ``signals/io``) is caught, as is a room importing a sibling of its line."""
    g = copy.deepcopy(graph(True))
    g.add_import(importer="coolmuscle.motor.state.firmware",
                 imported="coolmuscle.motor.signals.io")
    g.add_import(importer="coolmuscle.tools.batch.engine", imported="coolmuscle.tools.web.hub")
    assert sorted(rooms_against_the_order(g)) == [
        ("coolmuscle.motor.state.firmware", "coolmuscle.motor.signals.io", "state -> signals"),
        ("coolmuscle.tools.batch.engine", "coolmuscle.tools.web.hub", "batch -> web")]
    assert rooms_against_the_order(graph(True)) == []         # the cached graph untouched


# -- plug-ins named by a string ------------------------------------------------------------

def _source_root() -> Path:
    spec = importlib.util.find_spec("coolmuscle")
    assert spec is not None and spec.submodule_search_locations
    return Path(list(spec.submodule_search_locations)[0])


def _tree(module: str) -> ast.Module | None:
    """The syntax tree of one of the package's modules (None: no source file)."""
    base = _source_root().parent / Path(*module.split("."))
    for path in (base / "__init__.py", base.with_suffix(".py")):
        if path.is_file():
            return ast.parse(path.read_text(encoding="utf-8"), str(path))
    return None


def _defines(tree: ast.Module, name: str) -> bool:
    """Whether a module binds ``name`` at its top level."""
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            if node.name == name:
                return True
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            if any((alias.asname or alias.name.split(".")[0]) == name for alias in node.names):
                return True
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            if any(isinstance(t, ast.Name) and t.id == name for t in targets):
                return True
    return False


@cache
def plugins() -> tuple[tuple[str | None, str, str], ...]:
    """Every plug-in named by a string: ``(loader, module, attribute)``.

    A ``"coolmuscle.x.y:attr"`` string in a module of the package is loaded by that
    module (a registry such as ``frontends/transports``' ``BUILTIN``); an entry point of
    pyproject.toml by the module of ``ENTRY_POINT_LOADERS`` for its group, a script by
    the installer (loader ``None``: outside the package)."""
    found: list[tuple[str | None, str, str]] = []
    for module in sorted(graph(True).modules):
        tree = _tree(module)
        for node in ast.walk(tree) if tree is not None else ():
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                match = _PLUGIN.fullmatch(node.value.strip())
                if match:
                    found.append((module, match.group(1), match.group(2)))
    project = tomllib.loads(PYPROJECT.read_text(encoding="utf-8"))["project"]
    groups: dict[str, dict[str, str]] = dict(project.get("entry-points", {}))
    groups.update({group: project[group] for group in SCRIPT_GROUPS if group in project})
    for group, entries in sorted(groups.items()):
        for target in entries.values():
            match = _PLUGIN.fullmatch(target.replace(" ", ""))
            if match is None:
                continue                    # a plug-in of another package
            assert group in ENTRY_POINT_LOADERS or group in SCRIPT_GROUPS, \
                f"entry-point group {group!r}: name the module that loads it"
            found.append((ENTRY_POINT_LOADERS.get(group), match.group(1), match.group(2)))
    return tuple(found)


def with_plugins(g: grimp.ImportGraph,
                 named: tuple[tuple[str | None, str, str], ...]) -> grimp.ImportGraph:
    """A copy of ``g`` with each plug-in an import of its loader."""
    g = copy.deepcopy(g)
    for loader, module, _attr in named:
        if loader is not None and module in g.modules:
            g.add_import(importer=loader, imported=module)
    return g


@cache
def plugged(type_checking: bool) -> grimp.ImportGraph:
    return with_plugins(graph(type_checking), plugins())


def test_plugins_named_by_a_string_exist() -> None:
    named = plugins()                   # the scan sees the registry and the scripts
    assert ("coolmuscle.frontends.transports", "coolmuscle.frontends.transports.tcp",
            "TcpTransport") in named
    assert (None, "coolmuscle.tools.cli.entry", "main") in named
    modules = graph(True).modules
    missing = []
    for loader, module, attr in named:
        tree = _tree(module) if module in modules else None
        if tree is None or not _defines(tree, attr.split(".")[0]):
            missing.append((loader, f"{module}:{attr}"))
    assert missing == []


def test_a_plugin_named_against_the_layers_is_caught() -> None:
    """The transport registry's entry that named the web page's class in tools/ from
    frontends/ (an import the graph alone cannot see) fails the layer test."""
    upward = (("coolmuscle.frontends.transports", "coolmuscle.tools.web.server",
               "WebTransport"),)
    assert illegal_layer_imports(with_plugins(graph(False), upward)) != []
    assert illegal_layer_imports(with_plugins(graph(False), ())) == []


# -- the fieldbus rooms: engines that never name the device they serve -----------------
ETHERCAT_ENGINE = "coolmuscle.frontends.ethercat.engine"
CIP = "coolmuscle.frontends.enip.cip"
CM1 = "coolmuscle.frontends.enip.cm1"
#: The words that name the product: the engine is configured by a slave description.
PRODUCT_NAMES = re.compile(r"cool|muscle|bridge|EB0", re.IGNORECASE)


def _within(module: str, package: str) -> bool:
    return module == package or module.startswith(package + ".")


def imports_leaving(g: grimp.ImportGraph, package: str) -> set[tuple[str, str]]:
    """(importer, imported) pairs where a module of ``package`` imports a coolmuscle
    module outside it."""
    return {(m, i) for m in g.modules if _within(m, package)
            for i in g.find_modules_directly_imported_by(m) if not _within(i, package)}


@pytest.mark.parametrize("type_checking", [False, True], ids=["runtime", "with-type-only"])
def test_the_ethercat_engine_imports_only_itself(type_checking: bool) -> None:
    """Not the bridge, not motor/, chain/ or device/: the engine is the bridge's, not
    the other way round (KickCAT: "the simulator core never names a profile")."""
    g = graph(type_checking)
    assert len([m for m in g.modules if _within(m, ETHERCAT_ENGINE)]) >= 10
    assert imports_leaving(g, ETHERCAT_ENGINE) == set()
    bitten = graph.__wrapped__(type_checking)
    bitten.add_import(importer=ETHERCAT_ENGINE + ".slave",
                      imported="coolmuscle.frontends.ethercat.bridge.identity")
    assert imports_leaving(bitten, ETHERCAT_ENGINE) == {
        (ETHERCAT_ENGINE + ".slave", "coolmuscle.frontends.ethercat.bridge.identity")}


def test_the_ethercat_engine_names_no_product() -> None:
    import coolmuscle.frontends.ethercat.engine as engine
    sources = sorted(Path(engine.__path__[0]).glob("*.py"))
    assert len(sources) >= 10
    named = {f"{p.name}:{n}": line.strip() for p in sources
             for n, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
             if PRODUCT_NAMES.search(line)}
    assert named == {}
    assert PRODUCT_NAMES.search("the EB02 bridge")            # the pattern bites


@pytest.mark.parametrize("type_checking", [False, True], ids=["runtime", "with-type-only"])
def test_the_cip_machinery_imports_nothing_of_the_cm1_module(type_checking: bool) -> None:
    g = graph(type_checking)
    assert g.chain_exists(importer=CM1, imported=CIP, as_packages=True)     # cm1 uses cip
    assert not g.chain_exists(importer=CIP, imported=CM1, as_packages=True)
    assert {i for _m, i in imports_leaving(g, CIP)} <= {"coolmuscle.errors"}

"""The pytest plug-in: coolmuscle's fixtures, assertions and bank coverage in a user's tests.

Installed with the package (entry point ``pytest11``: pytest loads it by itself), or
named with ``-p coolmuscle.testing.plugin``.  Loading it imports pytest and the standard
library only; a fixture loads what it uses when a test uses it, so ``pytest --co`` of
a project stays as fast as without it, and a run that uses none of it runs as before.

Fixtures (docs/testing-your-project.md):

``cm_chain``
    a :class:`~coolmuscle.testing.rig.ChainRig`: a chain in virtual time, recorded, with
    ``send``/``run``/``load``/``port`` and the assertions of ``expect(motor)``.  Options
    by ``@pytest.mark.cm_chain(motors=2, firmware="rt3", machine="axis.toml",
    banks="banks/pick.cml", setup=["K23.1=17"], plant={...})`` or an indirect
    parameter (a dict); ``cm_chain_factory(**options)`` builds more.
``cm_sim``
    a served ``coolmuscle sim`` (:class:`~coolmuscle.testing.served.ServedSim`) on free
    ports, any front door: ``@pytest.mark.cm_sim(tcp=True, modbus_tcp=True, pty=True,
    enip=True, web=True, motors=2, firmware="cm1", machine=..., args=[...])``; its URL
    and ports are attributes.  ``cm_sim_factory(**options)`` starts more.
``cm_lab``
    an EtherCAT lab: a veth pair, the bridge served on the far end (``cm_lab.master_if``
    for the test's master, ``cm_lab.sim``); skipped with the reason where the machine
    cannot make one (:mod:`.lab`).

Everything a fixture starts is stopped after the test, passed or failed, and then
checked to be gone (no process, port, namespace or link left: :mod:`.ledger`).

Options: ``--cm-coverage`` (bank coverage table), ``--cm-coverage-xml PATH`` (Cobertura
XML, implies it), ``--cm-plots DIR`` (a failing motion assertion draws the chain's trace
into ``DIR``), ``--cm-ledger PATH`` (what the fixtures started, for a check after the run).
"""

from __future__ import annotations

import itertools
import os
import re
import signal
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

if TYPE_CHECKING:
    from .coverage import BankCoverage
    from .lab import LabLink
    from .ledger import Ledger
    from .rig import ChainRig
    from .served import ServedSim

CHAIN_OPTIONS = ("motors", "firmware", "machine", "banks", "setup", "plant", "pacing",
                 "state_dir")
SIM_OPTIONS = ("motors", "firmware", "machine", "state", "tcp", "modbus_tcp", "pty", "enip",
               "web", "rfc2217", "args")


@dataclass
class _Run:
    """What the plug-in keeps for one pytest run (``config.stash``)."""

    config: pytest.Config
    coverage: BankCoverage | None = None
    ledger: Ledger | None = None
    names: Iterator[int] = field(default_factory=itertools.count)

    @property
    def covering(self) -> bool:
        return bool(self.config.getoption("cm_coverage")
                    or self.config.getoption("cm_coverage_xml"))

    def bank_coverage(self) -> BankCoverage | None:
        if self.coverage is None and self.covering:
            from .coverage import BankCoverage
            self.coverage = BankCoverage()
        return self.coverage

    def the_ledger(self) -> Ledger:
        if self.ledger is None:
            from .ledger import TOKEN_VARIABLE, Ledger
            token = os.environ.get(TOKEN_VARIABLE) or uuid.uuid4().hex[:12]
            path = self.config.getoption("cm_ledger")
            self.ledger = Ledger(token, Path(path) if path else None)
        return self.ledger


_RUN = pytest.StashKey[_Run]()


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("coolmuscle", "coolmuscle: virtual Cool Muscle motors")
    group.addoption("--cm-coverage", action="store_true", default=False,
                    help="report which lines of the program and ladder banks ran")
    group.addoption("--cm-coverage-xml", metavar="PATH", default=None,
                    help="write the bank coverage as Cobertura XML (implies --cm-coverage)")
    group.addoption("--cm-plots", metavar="DIR", default=None,
                    help="a failing motion assertion draws the chain's trace into DIR")
    group.addoption("--cm-ledger", metavar="PATH", default=None,
                    help="append what the fixtures start (processes, ports, namespaces) "
                         "to PATH, one JSON object a line")


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "cm_chain(motors=1, firmware='cm2', machine=None, "
                            "banks=None, setup=(), plant=None): the chain of cm_chain")
    config.addinivalue_line("markers", "cm_sim(tcp=True, modbus_tcp=False, pty=False, "
                            "enip=False, web=False, motors=1, firmware=None, machine=None, "
                            "args=()): the served simulator of cm_sim")
    config.stash[_RUN] = _Run(config)


def _options(request: pytest.FixtureRequest, marker: str,
             allowed: tuple[str, ...]) -> dict[str, Any]:
    """The marker's keywords, updated by an indirect parameter (a dict)."""
    options: dict[str, Any] = {}
    for mark in reversed(list(request.node.iter_markers(marker))):
        options.update(mark.kwargs)
    param = getattr(request, "param", None)
    if isinstance(param, dict):
        options.update(param)
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        raise pytest.UsageError(f"{marker}: unknown option(s) {', '.join(unknown)} "
                                f"(known: {', '.join(allowed)})")
    return options


def _test_name(request: pytest.FixtureRequest, number: int) -> str:
    name = re.sub(r"[^\w.-]+", "_", request.node.nodeid).strip("_")
    return f"{name}-{number}" if number else name


def _find(request: pytest.FixtureRequest, path: str | Path) -> Path:
    for candidate in (Path(path), request.path.parent / path,
                      request.config.rootpath / path):
        if candidate.exists():
            return candidate
    raise FileNotFoundError(f"no file {path} (looked beside {request.path.name} and in "
                            f"{request.config.rootpath})")


# -- cm_chain -----------------------------------------------------------------------------
@pytest.fixture
def cm_chain_factory(request: pytest.FixtureRequest) -> Iterator[Callable[..., ChainRig]]:
    """``cm_chain_factory(motors=1, firmware="cm2", machine=None, banks=None, setup=(),
    plant=None)``: chains in virtual time (:class:`~coolmuscle.testing.rig.ChainRig`),
    closed after the test."""
    from .rig import ChainRig, build_chain
    run = request.config.stash[_RUN]
    plots = request.config.getoption("cm_plots")
    made: list[ChainRig] = []

    def make(**options: Any) -> ChainRig:
        unknown = sorted(set(options) - set(CHAIN_OPTIONS))
        if unknown:
            raise TypeError(f"cm_chain: unknown option(s) {', '.join(unknown)}")
        banks = options.pop("banks", None)
        if options.get("machine") is not None and not hasattr(options["machine"], "motors"):
            options["machine"] = _find(request, options["machine"])
        rig = ChainRig(build_chain(**options), base=request.path.parent,
                       root=request.config.rootpath, coverage=run.bank_coverage(),
                       plot_dir=Path(plots) if plots else None,
                       name=_test_name(request, len(made)))
        made.append(rig)
        for path in [banks] if isinstance(banks, (str, Path)) else banks or ():
            rig.load(path)
        return rig
    yield make
    for rig in made:
        rig.close()


@pytest.fixture
def cm_chain(request: pytest.FixtureRequest,
             cm_chain_factory: Callable[..., ChainRig]) -> ChainRig:
    """A chain in virtual time (options: ``@pytest.mark.cm_chain(...)``)."""
    return cm_chain_factory(**_options(request, "cm_chain", CHAIN_OPTIONS))


# -- cm_sim -------------------------------------------------------------------------------
def _stop(sim: ServedSim, ledger: Ledger, entries: list[dict[str, Any]]) -> list[str]:
    """Stop a served sim as a user would (SIGINT), kill what is left; what remains."""
    from .ledger import end_group, leftovers
    try:
        sim.stop(signal.SIGINT, timeout=10)
    except Exception:            # it did not stop in time: the group is killed below
        pass
    sim.close()
    for entry in entries:
        if entry["kind"] == "path":
            Path(entry["path"]).unlink(missing_ok=True)      # a link SIGKILL left
    left = leftovers(entries)
    if left:
        end_group(sim.pid)
    return left


def _start_sim(request: pytest.FixtureRequest, log: Path, options: dict[str, Any],
               prefix: list[str] | None = None, extra: tuple[str, ...] = ()) -> tuple[
                   ServedSim, list[dict[str, Any]]]:
    from .ledger import TOKEN_VARIABLE
    from .served import ServedSim, child_env
    ledger = request.config.stash[_RUN].the_ledger()
    args = [str(a) for a in options.pop("args", ())] + list(extra)
    for key, flag in (("motors", "--motors"), ("firmware", "--firmware")):
        if options.get(key) is not None:
            args += [flag, str(options.pop(key))]
        options.pop(key, None)
    if options.get("enip") and "--firmware" not in args:
        args += ["--firmware", "cm1"]                 # the EtherNet/IP module is a CM1's
    machine = options.pop("machine", None)
    if machine is not None:
        args += ["--machine", str(_find(request, machine).resolve())]
    pty = options.get("pty")
    if isinstance(pty, str):
        options["pty"] = Path(pty)
    env = child_env()
    env[TOKEN_VARIABLE] = ledger.token                 # every process it starts carries it
    sim = ServedSim(log, *args, prefix=prefix or (), env=env, **options)
    entries = [ledger.note("process", pgid=sim.pid, what=f"coolmuscle {' '.join(sim.args)}")]
    if not prefix:                                     # ports inside a namespace are its own
        entries += [ledger.note("port", proto=proto, port=port) for proto, port in sim.ports]
    if isinstance(options.get("pty"), Path):
        entries.append(ledger.note("path", path=str(options["pty"])))
    return sim, entries


@pytest.fixture
def cm_sim_factory(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
                   ) -> Iterator[Callable[..., ServedSim]]:
    """``cm_sim_factory(tcp=True, modbus_tcp=False, pty=False, enip=False, web=False,
    motors=1, firmware=None, machine=None, state=None, args=())``: served sims on free
    ports, stopped after the test and checked to be gone."""
    started: list[tuple[ServedSim, list[dict[str, Any]]]] = []
    logs = tmp_path_factory.mktemp("cm_sim")
    ledger = request.config.stash[_RUN].the_ledger()

    def start(**options: Any) -> ServedSim:
        unknown = sorted(set(options) - set(SIM_OPTIONS))
        if unknown:
            raise TypeError(f"cm_sim: unknown option(s) {', '.join(unknown)}")
        sim, entries = _start_sim(request, logs / f"sim{len(started)}.log", dict(options))
        started.append((sim, entries))
        return sim
    yield start
    left = [problem for sim, entries in reversed(started)
            for problem in _stop(sim, ledger, entries)]
    if left:
        pytest.fail("cm_sim left behind: " + "; ".join(left), pytrace=False)


@pytest.fixture
def cm_sim(request: pytest.FixtureRequest,
           cm_sim_factory: Callable[..., ServedSim]) -> ServedSim:
    """A served simulator on free ports (options: ``@pytest.mark.cm_sim(...)``)."""
    return cm_sim_factory(**_options(request, "cm_sim", SIM_OPTIONS))


# -- cm_lab -------------------------------------------------------------------------------
@dataclass
class Lab:
    """The ``cm_lab`` fixture: the link (``master_if`` is the test's end) and the sim
    serving the EtherCAT bridge on the other end."""

    link: LabLink
    sim: ServedSim

    @property
    def master_if(self) -> str:
        return self.link.master_if


@pytest.fixture
def cm_lab(request: pytest.FixtureRequest,
           tmp_path_factory: pytest.TempPathFactory) -> Iterator[Lab]:
    """An EtherCAT lab for the test (``@pytest.mark.cm_sim(args=["--bridge", "EB01"])``
    passes options to its sim); skipped with the reason where none can be made."""
    from .lab import LabUnavailable, open_lab, unavailable
    reason = unavailable()
    if reason is not None:
        pytest.skip(reason)
    run = request.config.stash[_RUN]
    ledger = run.the_ledger()
    prefix = f"cml{ledger.token[:6]}{next(run.names) % 100:02d}"
    log = tmp_path_factory.mktemp("cm_lab") / "sim.log"
    try:
        with open_lab(prefix) as link:
            names = ledger.note("namespace", name=link.namespace,
                                links=[link.master_if, link.slave_if])
            options = {k: v for k, v in _options(request, "cm_sim", SIM_OPTIONS).items()
                       if k in ("motors", "firmware", "machine", "args")}
            sim, entries = _start_sim(request, log, {**options, "tcp": False},
                                      prefix=link.slave_prefix,
                                      extra=("--ethercat", link.slave_if))
            try:
                yield Lab(link, sim)
            finally:
                left = _stop(sim, ledger, entries)
    except LabUnavailable as exc:
        pytest.skip(str(exc))
    from .ledger import leftovers
    left += leftovers([names])
    if left:
        pytest.fail("cm_lab left behind: " + "; ".join(left), pytrace=False)


# -- coverage and the end of the run ---------------------------------------------------------
def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    run = session.config.stash.get(_RUN, None)
    if run is None or run.coverage is None:
        return
    workeroutput = getattr(session.config, "workeroutput", None)
    if workeroutput is not None:                       # an xdist worker: to the controller
        workeroutput["cm_coverage"] = run.coverage.data()
        return
    xml = session.config.getoption("cm_coverage_xml")
    if xml:
        from .. import __version__
        run.coverage.write_xml(Path(xml), session.config.rootpath, __version__)


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node: Any, error: Any) -> None:
    """pytest-xdist: a worker's bank coverage joins the controller's."""
    data = getattr(node, "workeroutput", {}).get("cm_coverage")
    if data is None:
        return
    run = node.config.stash[_RUN]
    coverage = run.bank_coverage()
    if coverage is not None:
        coverage.merge(data)


def pytest_terminal_summary(terminalreporter: Any, exitstatus: int,
                            config: pytest.Config) -> None:
    run = config.stash.get(_RUN, None)
    if run is None or not run.covering or hasattr(config, "workeroutput"):
        return
    terminalreporter.write_sep("-", "coolmuscle bank coverage")
    coverage = run.bank_coverage()
    if coverage is None or not coverage.files:
        terminalreporter.write_line("no bank ran on a chain of cm_chain")
        return
    for line in coverage.table():
        terminalreporter.write_line(line)
    xml = config.getoption("cm_coverage_xml")
    if xml:
        terminalreporter.write_line(f"Cobertura XML written to {xml}")

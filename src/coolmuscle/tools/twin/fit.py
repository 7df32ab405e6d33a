"""``coolmuscle fit``: the machine file's load and servo model fitted to a captured session.

Least squares (``scipy.optimize.least_squares``, trust region, bounded by what a
machine file may hold) over replays of the capture in virtual time (:mod:`.replay`):
each evaluation replays the whole session on a virtual motor with the trial values and
compares every polled value (6.6 ``?95`` Pe, ``?96`` Px, ``?97`` Sx, ``?98`` Ix) with
the real one, unrounded.  Each residual is divided by what it may be off by with the
right parameters: 0.5 (rounding) + the noise (1 unit) + how fast the real quantity
moved times half the time its poll took (the instant it was read is unknown within
that window), so a weighted residual RMS near 1 means "as good as the data allows".

After the fit: the covariance ``s² (JᵀJ)⁻¹`` of the Jacobian at the solution gives each
parameter's standard error.  That is the error that averages out over many polls; the
replies' rounding to whole units does not when the quantity holds still (a friction
read from a cruising ``Ix`` of 9.4 % is 9 % at every poll), so each parameter also gets
its *resolution*: the change that moves no polled value by more than half a unit
(0.5 / the largest |d value / d parameter|).  The 95 % interval printed is the
value ± (1.96 standard errors + the resolution).  A parameter that changes no polled
value, or two that the session cannot tell apart, are refused by name (exit 2, nothing
written), as is a fit that did not converge within ``max_replays`` replays.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ...chain.machine import Machine, parse_machine
from ...needs import needs_extra
from .compare import load_machine_arg
from .params import FitError, Param, parse_params, with_values
from .plot import Panel, Series
from .replay import Replay, replay
from .session import POLLED, Poll, Session, parse_poll, read_session

with needs_extra("twin", "coolmuscle fit"):
    import numpy as np
    import numpy.typing as npt

__all__ = ["FitResult", "fit", "fit_session"]

Array = npt.NDArray[np.float64]

#: Replays a fit may take (each Jacobian costs one per parameter).
MAX_REPLAYS = 300
#: Relative step of the finite-difference Jacobian (of value / scale).
DIFF_STEP = 1e-3
NOISE = 1.0             # units, beyond the rounding (as compare's default)
SAMPLE = 0.001          # s each side of a poll's window
#: Parameters are told apart when the smallest singular value of the column-normalised
#: Jacobian is at least this fraction of the largest (two parameters at 0.01: their
#: estimates correlate by 0.9998).
MIN_SINGULAR = 0.01


def _scipy() -> Any:
    with needs_extra("twin", "coolmuscle fit"):
        from scipy import optimize  # type: ignore[import-untyped]
    return optimize


@dataclass
class FitResult:
    """The outcome of :func:`fit`: values, their standard errors, the residuals."""

    session: Session
    params: list[Param]
    start: list[float]
    values: list[float]
    stderr: list[float]
    resolution: list[float]          # the change that moves no polled value by 0.5 unit
    rms_start: float                 # weighted residual RMS at the start
    rms: float                       # ... at the solution
    replays: int
    seconds: float
    machine: Machine
    base_path: Path | None
    quantity_rms: dict[str, float] = field(default_factory=dict)   # real - fitted, units
    panels: list[Panel] = field(default_factory=list)
    message: str = ""

    def lines(self) -> list[str]:
        """The parameters, one line each: value, standard error, resolution, 95 %
        interval (± 1.96 standard errors + the resolution), start."""
        width = max(len(p.name) for p in self.params)
        out = []
        for p, v, se, res, v0 in zip(self.params, self.values, self.stderr, self.resolution,
                                     self.start, strict=True):
            half = 1.96 * se + res
            out.append(f"  {p.name:<{width}} = {_fmt(v)} {p.kind.unit}: standard error "
                       f"{se:.2g}{_percent(se, v)}, resolution {res:.2g}{_percent(res, v)}, "
                       f"95 % {_fmt(v - half)} .. {_fmt(v + half)}; start {_fmt(v0)}")
        return out

    def machine_text(self) -> str:
        """The machine file with the fitted values (the base file's other keys and
        comments kept; needs tomlkit)."""
        return _machine_text(self)

    def write_machine(self, path: str | Path) -> Path:
        """Write :meth:`machine_text` to ``path`` whole or not at all."""
        from .output import write_atomic
        return write_atomic(Path(path), self.machine_text().encode("utf-8"))


def _fmt(value: float) -> str:
    return f"{value:.6g}"


def _percent(part: float, value: float) -> str:
    return f" ({100 * part / abs(value):.2f} %)" if value else ""


# -- the residuals --------------------------------------------------------------------
class _Problem:
    """The session's polls, their weights, and the replays the fit asks for."""

    def __init__(self, session: Session, base: Machine | None, params: list[Param],
                 max_replays: int, on_replay: Callable[[int, float], None] | None) -> None:
        self.session = session
        self.base = base
        self.params = params
        self.scales: Array = np.array([p.kind.scale for p in params], dtype=np.float64)
        self.polls = session.polls
        self.real: Array = np.array([p.value for p in self.polls], dtype=np.float64)
        self.sigma = _sigmas(self.polls)
        self.index = {(p.sent_index, p.motor, p.quantity): i for i, p in enumerate(self.polls)}
        self.max_replays = max_replays
        self.replays = 0
        self.on_replay = on_replay

    def machine(self, u: Array) -> Machine:
        return with_values(self.base, self.params, [float(x) for x in u * self.scales])

    def virtual(self, u: Array) -> tuple[Array, Replay]:
        if self.replays >= self.max_replays:
            raise FitError(f"the fit did not converge within {self.max_replays} replays "
                           "(fewer --params, a better start from --machine, or a longer "
                           "session)")
        self.replays += 1
        rep = replay(self.session, self.machine(u))
        if rep.failure is not None:
            values = ", ".join(f"{p.name}={_fmt(v)}" for p, v in
                               zip(self.params, u * self.scales, strict=True))
            raise FitError(f"the virtual motor stopped at {values}: {rep.failure}")
        out = np.array(self.real)            # a poll without a reply: no residual
        for j, value in rep.exact.items():
            found = parse_poll(rep.lines[j].text)
            assert found is not None
            i = self.index.get((rep.after[j], found[1], found[0]))
            if i is not None:
                out[i] = value
        return out, rep

    def residuals(self, u: Array) -> Array:
        values, _ = self.virtual(u)
        r: Array = (values - self.real) / self.sigma
        if self.on_replay is not None:
            self.on_replay(self.replays, float(np.sqrt(np.mean(r * r))))
        return r


def _sigmas(polls: list[Poll]) -> Array:
    """What each real value may be off by: rounding + noise + its rate x half its window."""
    sigma = np.full(len(polls), 0.5 + NOISE)
    series: dict[tuple[int, str], list[int]] = {}
    for i, p in enumerate(polls):
        series.setdefault((p.motor, p.quantity), []).append(i)
    for members in series.values():
        for k, i in enumerate(members):
            a, b = members[max(k - 1, 0)], members[min(k + 1, len(members) - 1)]
            dt = polls[b].time - polls[a].time
            if dt <= 0:
                continue
            rate = abs(polls[b].value - polls[a].value) / dt
            window = polls[i].time - polls[i].asked + 2 * SAMPLE
            sigma[i] += rate * window / 2
    return sigma


# -- the fit --------------------------------------------------------------------------
def fit(session: Session, base: Machine | None = None, params: list[Param] | None = None,
        *, base_path: Path | None = None, max_replays: int = MAX_REPLAYS,
        on_replay: Callable[[int, float], None] | None = None) -> FitResult:
    """Fit ``params`` of ``base`` (None: the default machine) to ``session``."""
    optimize = _scipy()
    polled = {p.motor for p in session.polls}
    if not session.polls:
        raise FitError(f"{session.source}: the session polls no value (?95, ?96, ?97, ?98): "
                       "nothing to fit (docs/twin.md 'A session the fit can use')")
    params = params if params is not None else parse_params(None, session.motors, polled)
    began = time.perf_counter()
    start = _start_values(session, base, params)
    problem = _Problem(session, base, params, max_replays, on_replay)
    u0 = np.array(start) / problem.scales
    lo = np.array([p.bounds[0] for p in params]) / problem.scales
    hi = np.array([p.bounds[1] for p in params]) / problem.scales
    u0 = np.clip(u0, lo, hi)
    first, _ = problem.virtual(u0)
    r0 = (first - problem.real) / problem.sigma
    result = optimize.least_squares(problem.residuals, u0, bounds=(lo, hi), method="trf",
                                    diff_step=DIFF_STEP, x_scale=1.0, ftol=1e-8, xtol=1e-8,
                                    gtol=1e-8, max_nfev=max_replays)
    if result.status <= 0 or not np.all(np.isfinite(result.fun)):
        raise FitError(f"the fit did not converge ({result.message}) after "
                       f"{problem.replays} replays")
    u = result.x
    stderr = _stderr(problem, result.jac, result.fun)
    resolution = _resolution(problem, result.jac)
    fitted, rep = problem.virtual(u)
    values = [float(x) for x in u * problem.scales]
    rms = float(np.sqrt(np.mean(result.fun ** 2)))
    out = FitResult(session, params, start, values, [float(s) for s in stderr],
                    [float(r) for r in resolution], float(np.sqrt(np.mean(r0 ** 2))), rms,
                    problem.replays,
                    time.perf_counter() - began, problem.machine(u), base_path,
                    message=str(result.message))
    out.quantity_rms = _quantity_rms(session.polls, problem.real, fitted)
    out.panels = _panels(session.polls, first, fitted)
    return out


def _start_values(session: Session, base: Machine | None, params: list[Param]) -> list[float]:
    """The base machine's values (the motor's own for keys it leaves out); a stopper it
    lacks starts just beyond the farthest position the session polled."""
    from ...chain.daisy import Chain
    chain = Chain(None, session.motors, firmware=session.firmware, machine=base)
    try:
        out = []
        specs = {a.motor: a for a in (base.axes if base is not None else [])}
        for p in params:
            plant_value = chain.machine_data(p.motor).get(p.kind.key, 0.0)
            value = p.value(specs.get(p.motor), plant_value)
            if value is None:
                value = _stopper_guess(session, p)
            out.append(value)
        return out
    finally:
        chain.close()


def _stopper_guess(session: Session, param: Param) -> float:
    positions = [p.value for p in session.polls if p.quantity == "Px" and p.motor == param.motor]
    if not positions:
        raise FitError(f"{param.name}: the machine file has no such stopper and the session "
                       f"polls no position of motor {param.motor} (?96) to start from")
    return max(positions) + 1.0 if param.kind.key == "cw" else min(positions) - 1.0


def _stderr(problem: _Problem, jac: Array, fun: Array) -> Array:
    """Standard errors (in values) from cov = s² (JᵀJ)⁻¹; FitError naming a parameter the
    session does not determine."""
    params = problem.params
    norms = np.linalg.norm(jac, axis=0)
    top = float(norms.max()) if len(norms) else 0.0
    for p, n in zip(params, norms, strict=True):
        if n <= 1e-9 * max(top, 1e-300):
            raise FitError(f"{p.name} is not identifiable from this session: it changes no "
                           f"polled value (docs/twin.md 'A session the fit can use')")
    m, n = jac.shape
    _check_apart(params, jac / norms)
    s2 = float(fun @ fun) / max(m - n, 1)
    cov = np.linalg.inv(jac.T @ jac) * s2
    se: Array = np.sqrt(np.clip(np.diag(cov), 0.0, None)) * problem.scales
    return se


def _resolution(problem: _Problem, jac: Array) -> Array:
    """Per parameter (in values): the change that moves no polled value by more than half
    a unit of its reply, 0.5 / max |d value / d parameter| (the residuals' Jacobian times
    their weights, per unit of the parameter)."""
    slopes = np.abs(jac * problem.sigma[:, None]).max(axis=0) / problem.scales
    out: Array = 0.5 / np.maximum(slopes, 1e-300)
    return out


def _check_apart(params: list[Param], unit_jac: Array) -> None:
    """FitError naming the parameters whose effects the session cannot tell apart: those
    that weigh in the direction the (column-normalised) Jacobian barely sees."""
    if len(params) < 2:
        return
    _, sv, vt = np.linalg.svd(unit_jac, full_matrices=False)
    if sv[-1] > MIN_SINGULAR * sv[0]:
        return
    weights = np.abs(vt[-1])
    names = [p.name for p, w in zip(params, weights, strict=True) if w > 0.2 * weights.max()]
    listed = ", ".join(names[:-1]) + f" and {names[-1]}" if len(names) > 1 else names[0]
    raise FitError(f"{listed} cannot be told apart in this session (their effects on the "
                   f"polled values are alike: singular value ratio {sv[-1] / sv[0]:.1e}); "
                   "fit fewer of them, or capture a session that moves them apart "
                   "(docs/twin.md)")


def _quantity_rms(polls: list[Poll], real: Array, fitted: Array) -> dict[str, float]:
    out: dict[str, float] = {}
    for name in POLLED:
        mask = np.array([p.quantity == name for p in polls])
        if mask.any():
            d = real[mask] - fitted[mask]
            out[name] = float(np.sqrt(np.mean(d * d)))
    return out


def _panels(polls: list[Poll], start: Array, fitted: Array) -> list[Panel]:
    groups: dict[tuple[int, str], list[int]] = {}
    for i, p in enumerate(polls):
        groups.setdefault((p.motor, p.quantity), []).append(i)
    order = list(POLLED)
    panels = []
    for motor, quantity in sorted(groups, key=lambda k: (k[0], order.index(k[1]))):
        idx = groups[(motor, quantity)]
        times = [polls[i].time for i in idx]
        panels.append(Panel(motor, quantity, [
            Series("measured (real motor)", times, [float(polls[i].value) for i in idx], "real"),
            Series("start", times, [float(start[i]) for i in idx], "start"),
            Series("fitted", times, [float(fitted[i]) for i in idx], "fitted")]))
    return panels


# -- the machine file -----------------------------------------------------------------
def _machine_text(result: FitResult) -> str:
    with needs_extra("twin", "coolmuscle fit (writing machine files)"):
        import tomlkit
    path = result.base_path
    doc = tomlkit.parse(path.read_text(encoding="utf-8")) if path is not None \
        else tomlkit.document()
    axes = doc.get("axis")
    if axes is None:
        axes = tomlkit.aot()
        doc["axis"] = axes
    elif not isinstance(axes, list):          # a single [axis] table
        single = axes
        axes = tomlkit.aot()
        axes.append(single)
        doc["axis"] = axes
    for p, value in zip(result.params, result.values, strict=True):
        table = next((t for i, t in enumerate(axes) if t.get("motor", i + 1) == p.motor), None)
        if table is None:
            table = tomlkit.table()
            table["motor"] = p.motor
            axes.append(table)
        section = table.get(p.kind.section)
        if section is None:
            section = tomlkit.table()
            table[p.kind.section] = section
        section[p.kind.key] = float(f"{value:.6g}")
    fitted = ", ".join(f"{p.name} {_fmt(v)} ± {_fmt(se)}" for p, v, se in
                       zip(result.params, result.values, result.stderr, strict=True))
    text = (f"# fitted by coolmuscle fit to {Path(result.session.source).name}: {fitted} "
            f"(weighted residual RMS {result.rms:.3g})\n" + tomlkit.dumps(doc))
    parse_machine(text, "the fitted machine file")     # what is written loads
    return text


def fit_session(path: str | Path | Session, machine: str | Path | Machine | None = None,
                params: str | list[Param] | None = None, *, max_replays: int = MAX_REPLAYS,
                on_replay: Callable[[int, float], None] | None = None) -> FitResult:
    """Read the capture at ``path`` (or take a read :class:`Session`) and fit ``params``
    (names as ``--params``, or :class:`Param` objects; None: inertia, friction, kp) of
    ``machine`` (a path, a Machine; None: the capture's, else the default load)."""
    session = path if isinstance(path, Session) else read_session(path)
    base, _ = load_machine_arg(machine, session)
    base_path = None if isinstance(machine, Machine) else \
        (Path(machine) if machine is not None else session.machine)
    if not isinstance(params, list):
        params = parse_params(params, session.motors, {p.motor for p in session.polls})
    return fit(session, base, params, base_path=base_path, max_replays=max_replays,
               on_replay=on_replay)

"""Material parameters from a measured force curve: least squares over
simulations run as batches (docs/distributed.md, "Calibration").

    import tissue.fitting as tf
    m = tf.read_measurement("indentation.csv")          # time or depth, then force
    fit = tf.fit("block.xml", m, {"E": 3000.0})          # start values
    fit.params["E"], fit.interval["E"]                   # estimate, 95 % interval

Each iteration evaluates the residuals at the current parameters and the
forward-difference Jacobian as one batch: p + 1 variants (p parameters), on
a Dask cluster or in this process (tissue.distributed.run).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from . import distributed as td

#: Parameters fitted in log space (positive, spanning decades); the others
#: (nu, a Prony g) in their own units within their open range.
_LOG = ("E", "rho", "tau", "fibre_stiffness")
#: How far inside an open range a linear parameter's bound lies.
_EDGE = 1e-4


class MeasurementError(ValueError):
    """A measurement file or curve the fit cannot use, naming the row and the rule."""


@dataclass
class Measurement:
    """Measured force against time (s) or depth (m, the tool's travel since it first touched)."""
    kind: str           # "time" | "depth"
    x: np.ndarray
    force: np.ndarray   # N, the magnitude of the tool's force
    source: str = "<array>"
    rows: Optional[np.ndarray] = None  # the file's line of each point

    def check(self) -> None:
        where = lambda k: f"{self.source}:{self.rows[k]}" if self.rows is not None else f"{self.source}: point {k}"
        if self.kind not in ("time", "depth"):
            raise MeasurementError(f"{self.source}: kind '{self.kind}' must be time or depth")
        if len(self.x) != len(self.force):
            raise MeasurementError(f"{self.source}: {len(self.x)} x values but {len(self.force)} forces")
        if len(self.x) < 3:
            raise MeasurementError(f"{self.source}: {len(self.x)} rows; a fit needs at least 3")
        for k in range(len(self.x)):
            if not (math.isfinite(self.x[k]) and math.isfinite(self.force[k])):
                raise MeasurementError(f"{where(k)}: a value is not finite")
            if self.x[k] < 0:
                raise MeasurementError(f"{where(k)}: {self.kind} {self.x[k]:g} is negative")
            if k and not self.x[k] > self.x[k - 1]:
                raise MeasurementError(f"{where(k)}: {self.kind} {self.x[k]:g} does not follow {self.x[k - 1]:g}: "
                                       f"rows must be sorted by {self.kind}, strictly increasing")
        if not np.any(self.force != 0):
            raise MeasurementError(f"{self.source}: every force is 0: the measured curve never touches")


def read_measurement(path: str, kind: Optional[str] = None) -> Measurement:
    """A CSV of rows `x, force` (N): x is time (s) or depth (m). A header
    row names it (t / time, depth / d / indentation); without one, `kind`
    says (default time). Errors name the file, the row and the rule."""
    xs, fs, rows = [], [], []
    header_kind = None
    for line_no, text, cells in td.csv_rows(path):
        if len(cells) < 2:
            raise MeasurementError(f"{path}:{line_no}: '{text}' has {len(cells)} column; a row is x, force")
        try:
            x, F = float(cells[0]), float(cells[1])
        except ValueError:
            if not xs and header_kind is None:
                name = cells[0].lower().split("(")[0].split("[")[0].strip()
                if name in ("t", "time"):
                    header_kind = "time"
                    continue
                if name in ("d", "depth", "indentation", "delta"):
                    header_kind = "depth"
                    continue
                raise MeasurementError(f"{path}:{line_no}: header '{cells[0]}' names neither time (t, time) nor "
                                       f"depth (depth, d, indentation)")
            raise MeasurementError(f"{path}:{line_no}: '{text}' is not a row of numbers (x, force)")
        xs.append(x)
        fs.append(F)
        rows.append(line_no)
    if header_kind and kind and header_kind != kind:
        raise MeasurementError(f"{path}: its header says {header_kind}, the option says {kind}")
    m = Measurement(header_kind or kind or "time", np.array(xs), np.array(fs), path, np.array(rows))
    m.check()
    return m


def simulated_curve(result: td.VariantResult, kind: str, tool: int = 0) -> Tuple[np.ndarray, np.ndarray]:
    """A variant's (x, |F|) of one tool: against time, or against depth, the
    tip's travel since it first touched (the first tick with a force; the
    touch is placed half a tick's travel before it) up to its deepest point."""
    F = np.linalg.norm(result.force[:, tool], axis=1)
    if kind == "time":
        return np.concatenate([[0.0], result.time]), np.concatenate([[0.0], F])
    touching = np.nonzero(F > 0)[0]
    if len(touching) == 0:
        raise MeasurementError("the simulated tool never touches the tissue along its path: a depth curve "
                               "cannot be matched (check the path)")
    c = int(touching[0])
    tip = result.tip[:, tool]
    # the press direction at the touch, and half the last tick's travel before it
    prev = tip[c - 1] if c > 0 else tip[c]
    move = tip[c] - prev if c > 0 else (tip[min(c + 1, len(tip) - 1)] - tip[c])
    length = float(np.linalg.norm(move))
    if length == 0:
        raise MeasurementError("the simulated tool does not move when it first touches: a depth curve needs a press")
    direction = move / length
    depth = np.concatenate([[0.0], (tip[c:] - tip[c]) @ direction + (0.5 * length if c > 0 else 0.0)])
    force = np.concatenate([[0.0], F[c:]])
    # the press alone: each point deeper than every one before it, up to the deepest
    keep = np.concatenate([[True], depth[1:] > np.maximum.accumulate(depth)[:-1]])
    last = int(np.argmax(depth))
    keep[last + 1:] = False
    return depth[keep], force[keep]


@dataclass
class FitResult:
    """The estimates, their 95 % intervals, and the curves."""
    params: Dict[str, float]
    interval: Dict[str, Tuple[float, float]]
    start: Dict[str, float]
    residual_rms: float            # N, measured - fitted
    relative_rms: float            # residual_rms / max |measured|
    iterations: int                # residual evaluations (batches)
    variants: int                  # simulations run
    measurement: Measurement
    fitted: np.ndarray             # N at the measured x
    message: str = ""
    history: List[Tuple[Dict[str, float], float]] = field(default_factory=list)  # (params, cost) per evaluation

    def table(self) -> str:
        lines = [f"{'parameter':<18} {'start':>12} {'estimate':>12} {'95 % interval':>28}"]
        for k, v in self.params.items():
            lo, hi = self.interval[k]
            lines.append(f"{k:<18} {self.start[k]:>12.6g} {v:>12.6g}   [{lo:.6g}, {hi:.6g}]")
        lines.append(f"residual: {self.residual_rms:.4g} N rms ({100 * self.relative_rms:.3g} % of the largest "
                     f"measured force), {self.iterations} evaluations, {self.variants} simulations")
        return "\n".join(lines)


def _to_z(name: str, value: float) -> float:
    return math.log(value) if td.parse_parameter(name).quantity in _LOG else value


def _from_z(name: str, z: float) -> float:
    return math.exp(z) if td.parse_parameter(name).quantity in _LOG else z


def _bounds(name: str) -> Tuple[float, float]:
    q = td.parse_parameter(name).quantity
    if q in _LOG:
        return -np.inf, np.inf
    lo, hi = td.PARAMETER_RANGES[q]
    return lo + _EDGE * (hi - lo), hi - _EDGE * (hi - lo)


def fit(scene: str, measurement: Measurement, start: Mapping[str, float], *, path: Optional[np.ndarray] = None,
        fixed: Optional[Mapping[str, float]] = None, tool: int = 0, precision: str = "double",
        backend: Optional[str] = None, scheduler: Optional[str] = None, client=None, local: bool = True,
        step: float = 1e-3, max_evaluations: int = 30, log=None, depth: Optional[str] = "all") -> FitResult:
    """Least squares (scipy.optimize.least_squares, trust region reflective)
    of the simulated force magnitude against the measured one, residuals
    scaled by the largest measured force. start: the parameters to fit and
    their start values (names as tissue.distributed takes them); fixed: other
    overrides held. Each evaluation runs the current point and one forward
    step (relative `step`) per parameter as one batch: local=True in this
    process, else on `client` or `scheduler` (or a LocalCluster). Returns
    the estimates with 95 % intervals from the Jacobian at the solution
    (Student t over the residual's degrees of freedom)."""
    try:
        from scipy.optimize import least_squares
        from scipy.stats import t as student_t
    except ImportError:
        raise RuntimeError("tissue.fitting needs SciPy: apt-get install python3-scipy (or pip install scipy)") from None

    measurement.check()
    names = list(start)
    if not names:
        raise ValueError("fit: no parameter to fit")
    for n in names:
        td.parse_parameter(n).check(start[n])
    fixed = dict(fixed or {})
    for n in fixed:
        td.parse_parameter(n).check(fixed[n])
    m, p = len(measurement.x), len(names)
    if m <= p:
        raise MeasurementError(f"{measurement.source}: {m} rows for {p} parameters; a fit needs more rows than "
                               f"parameters")
    scale = float(np.max(np.abs(measurement.force)))
    duration = None
    if measurement.kind == "time":
        duration = float(measurement.x[-1])
    z0 = np.array([_to_z(n, start[n]) for n in names])
    lo, hi = np.array([_bounds(n)[0] for n in names]), np.array([_bounds(n)[1] for n in names])
    if np.any(z0 <= lo) or np.any(z0 >= hi):
        bad = names[int(np.nonzero((z0 <= lo) | (z0 >= hi))[0][0])]
        raise td.ParameterError(f"start value {bad} = {start[bad]:g} lies on or beyond its range's edge")
    cache: Dict[bytes, Tuple[np.ndarray, np.ndarray]] = {}
    state = {"evaluations": 0, "variants": 0, "history": []}

    def values(z) -> Dict[str, float]:
        return {n: _from_z(n, float(v)) for n, v in zip(names, z)}

    def residual_of(r: td.VariantResult, which: str) -> np.ndarray:
        if r.failure is not None:
            raise RuntimeError(f"fit: the simulation at {which} stopped: {r.failure}")
        x, F = simulated_curve(r, measurement.kind, tool)
        beyond = np.nonzero(measurement.x > x[-1] * (1 + 1e-9))[0]
        if len(beyond):
            k = int(beyond[0])
            row = f"{measurement.source}:{measurement.rows[k]}" if measurement.rows is not None else f"point {k}"
            raise MeasurementError(f"{row}: {measurement.kind} {measurement.x[k]:g} lies beyond the simulated "
                                   f"path's reach ({x[-1]:g}); give a longer or deeper path")
        return (np.interp(measurement.x, x, F) - measurement.force) / scale

    def evaluate(z: np.ndarray):
        key = z.tobytes()
        if key in cache:
            return cache[key]
        points = [z] + [z + step * np.eye(p)[j] * (1 if z[j] + step < hi[j] else -1) for j in range(p)]
        variants = [td.Variant(scene, {**fixed, **values(zz)}, path, tool, duration) for zz in points]
        result = td.run(variants, backend=backend, precision=precision, scheduler=scheduler, client=client,
                        local=local and scheduler is None and client is None, depth=depth)
        res = [residual_of(r, ", ".join(f"{k} = {v:.6g}" for k, v in values(zz).items()))
               for r, zz in zip(result.results, points)]
        J = np.stack([(res[j + 1] - res[0]) / (points[j + 1][j] - z[j]) for j in range(p)], axis=1)
        state["evaluations"] += 1
        state["variants"] += len(points)
        cost = 0.5 * float(res[0] @ res[0])
        state["history"].append((values(z), cost))
        if log is not None:
            log(f"evaluation {state['evaluations']}: " + ", ".join(f"{k} = {v:.6g}" for k, v in values(z).items()) +
                f"  rms {math.sqrt(2 * cost / m) * scale:.4g} N")
        cache[key] = (res[0], J)
        return cache[key]

    sol = least_squares(lambda z: evaluate(z)[0], z0, jac=lambda z: evaluate(z)[1], bounds=(lo, hi),
                        method="trf", x_scale=1.0, max_nfev=max_evaluations, xtol=1e-8, ftol=1e-10, gtol=1e-10)
    r, J = evaluate(sol.x)
    dof = m - p
    s2 = float(r @ r) / dof
    try:
        cov = np.linalg.inv(J.T @ J) * s2
    except np.linalg.LinAlgError:
        cov = np.full((p, p), np.inf)
    tq = float(student_t.ppf(0.975, dof))
    est, interval = values(sol.x), {}
    for j, n in enumerate(names):
        half = tq * math.sqrt(max(cov[j, j], 0.0))
        interval[n] = (_from_z(n, sol.x[j] - half), _from_z(n, sol.x[j] + half))
    rms = math.sqrt(float(r @ r) / m) * scale
    return FitResult(est, interval, dict(start), rms, rms / scale, state["evaluations"], state["variants"],
                     measurement, measurement.force + r * scale, sol.message, state["history"])

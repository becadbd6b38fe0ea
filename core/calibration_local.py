"""Local calibration of 1–3 model parameters in few evaluations (docs/validation.md
"Calibration"): the better of the given start (e.g. the values a stored diagnosis fitted) and a
coarse scan, then the bounded trust-region reflective least squares of Branch, Coleman & Li
(``scipy.optimize.least_squares``, method ``"trf"``) on a residual vector — for the validation,
:func:`railval.core.calibration.validation_residuals`, whose squared norm is the DynoTRAIN
objective :func:`railval.core.calibration.validation_objective`. The forward-difference
Jacobian columns are evaluated in one ``map`` batch (a worker pool); the best evaluated point is
returned with the tolerance that stopped the fit.

References
----------
M. A. Branch, T. F. Coleman, Y. Li, "A subspace, interior, and conjugate gradient method for
large-scale bound-constrained minimization problems", SIAM J. Sci. Comput. 21(1), 1–23, 1999
(the ``trf`` method of ``scipy.optimize.least_squares``, SciPy reference documentation).
M. D. McKay, R. J. Beckman, W. J. Conover, "A comparison of three methods for selecting values
of input variables in the analysis of output from a computer code", Technometrics 21(2), 1979.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence

import numpy as np
from scipy.optimize import least_squares

from railval.core.calibration import CalibrationResult, ParameterSpec, Progress, checked_specs
from railval.core.errors import InvalidParameter

#: residual entry standing for a diverged simulation (non-finite residuals)
_DIVERGED = 1e6

#: residual evaluations the trust-region stage may spend (``least_squares``' ``max_nfev``)
MAX_NFEV = 30

_TRF_STATUS = {-1: "improper input", 0: "evaluation budget (max_nfev) spent", 1: "gtol", 2: "ftol",
               3: "xtol", 4: "ftol and xtol"}


class _Vector:
    """Picklable: unit-cube-free search vector → residual vector (diverged → large, finite)."""

    def __init__(self, residuals: Callable[[dict[str, float]], np.ndarray], specs: Sequence[ParameterSpec]):
        self.residuals, self.specs = residuals, list(specs)

    def params(self, x: np.ndarray) -> dict[str, float]:
        return {s.name: s.from_search(float(v)) for s, v in zip(self.specs, x, strict=True)}

    def __call__(self, x: np.ndarray) -> np.ndarray:
        r = np.asarray(self.residuals(self.params(np.asarray(x, float))), dtype=float)
        return np.where(np.isfinite(r), r, _DIVERGED) if r.size else np.full(1, _DIVERGED)


class _Memo:
    """Counts every residual evaluation, keeps the best (smallest Σr²) point, and evaluates a
    batch of points through ``workers`` (a ``map``) or serially."""

    def __init__(self, f: _Vector, workers: Callable | None):
        self.f, self.workers, self.calls = f, workers, 0
        self.best_x: np.ndarray | None = None
        self.best_cost = math.inf
        self.cache: dict[tuple, np.ndarray] = {}

    def batch(self, xs: Sequence[np.ndarray]) -> list[np.ndarray]:
        keys = [tuple(np.round(np.asarray(x, float), 12)) for x in xs]
        todo = [k for k in dict.fromkeys(keys) if k not in self.cache]
        mapper = self.workers if (self.workers is not None and len(todo) > 1) else map
        for k, r in zip(todo, mapper(self.f, [np.array(k) for k in todo]), strict=True):
            r = np.asarray(r, float)
            self.cache[k], self.calls = r, self.calls + 1
            cost = float(r @ r)
            if cost < self.best_cost:
                self.best_x, self.best_cost = np.array(k, float), cost
        return [self.cache[k] for k in keys]

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return self.batch([x])[0]


def _scan_points(bounds: np.ndarray, n: int, seed: int) -> list[np.ndarray]:
    """Coarse scan: 5 evenly spaced interior points for one parameter, else a seeded Latin
    hypercube of 4·n + 1 points (McKay, Beckman & Conover 1979)."""
    lo, hi = bounds[:, 0], bounds[:, 1]
    if n == 1:
        return [np.array([lo[0] + (k + 0.5) / 5 * (hi[0] - lo[0])]) for k in range(scan_size(1))]
    from scipy.stats import qmc

    u = qmc.LatinHypercube(d=n, seed=seed).random(scan_size(n))
    return [lo + row * (hi - lo) for row in u]


def scan_size(n_parameters: int) -> int:
    """Points of the coarse scan of :func:`_scan_points`: 5 for one parameter, else 4·n + 1."""
    return 5 if n_parameters == 1 else 4 * n_parameters + 1


def local_max_evaluations(n_parameters: int, max_nfev: int = MAX_NFEV, start: bool = True) -> int:
    """Upper bound of the distinct residual evaluations of :func:`calibrate_local` (its
    ``n_evaluations``): the scan (:func:`scan_size`), the start point, and the trust-region
    stage — ``least_squares`` evaluates the residuals at most ``max_nfev`` times and the
    Jacobian at most as often (at the start and after each accepted step, SciPy reference
    documentation of ``least_squares``: ``nfev``, ``njev``), each Jacobian costing one
    evaluation per parameter beside the point already evaluated (the forward differences of
    :func:`calibrate_local`).

    Parameters
    ----------
    n_parameters, max_nfev : int
    start : bool
        Whether a start point is evaluated (every parameter has a start value).

    Returns
    -------
    int
    """
    if n_parameters < 1:
        raise InvalidParameter(f"n_parameters must be at least 1, got {n_parameters}")
    return scan_size(n_parameters) + int(start) + max_nfev * (1 + n_parameters)


def _start(memo: _Memo, specs: Sequence[ParameterSpec], bounds: np.ndarray,
           seed: int) -> tuple[np.ndarray, float | None, str]:
    """Evaluate the scan (and the start, when every spec has one) in one batch; return the
    best point, the objective at the start (or None) and which of the two the fit starts from."""
    scan = _scan_points(bounds, len(specs), seed)
    start_from, obj_start = "scan", None
    if all(s.start is not None for s in specs):
        x_start = np.array([s.to_search(s.start) for s in specs], dtype=float)
        r0 = memo.batch([x_start, *scan])[0]
        obj_start = float(r0 @ r0)
        start_from = "start" if obj_start <= memo.best_cost else "scan (better than the start)"
    else:
        memo.batch(scan)
    return memo.best_x, obj_start, start_from


def calibrate_local(residuals: Callable[[dict[str, float]], np.ndarray], specs: Sequence[ParameterSpec], *,
                    seed: int = 0, ftol: float = 1e-3, xtol: float = 1e-3, gtol: float = 1e-6,
                    max_nfev: int = MAX_NFEV, rel_step: float = 1e-2, workers: Callable | None = None,
                    progress: Progress | None = None) -> CalibrationResult:
    """Fit bounded parameters by trust-region reflective least squares on a residual vector.

    Start: the better of the ``start`` of every spec (when all are given, e.g. the values a
    stored diagnosis fitted) and the best point of a coarse scan (:func:`_scan_points`),
    evaluated together in one ``map`` batch.
    Then ``scipy.optimize.least_squares(method="trf", bounds)`` (Branch, Coleman & Li 1999)
    minimises ½‖r‖² with a forward-difference Jacobian whose columns x + h·e_j,
    h = ``rel_step``·(upper − lower) in search space, are evaluated in one ``map`` batch.
    Stops at ``ftol`` (relative cost decrease), ``xtol`` (relative step) or ``gtol`` (scaled
    gradient), scipy's definitions, or after ``max_nfev`` residual evaluations. The returned
    point is the best of every evaluated point (scan, start, Jacobian columns, trust-region
    steps), so a poor start can never give a worse answer than the scan.

    Parameters
    ----------
    residuals, specs : callable, sequence of ParameterSpec
        ``{name: value}`` → residual vector (``Σ r²`` is the objective); the parameters.
    seed : int
        Latin-hypercube seed of the scan for several parameters.
    ftol, xtol, gtol, max_nfev, rel_step : float, float, float, int, float
        Tolerances, residual-evaluation budget of the local stage, Jacobian step share.
    workers, progress : callable or None
        ``map(func, iterable)`` for batches; ``progress(stage, fraction, info)``.

    Returns
    -------
    CalibrationResult
        ``method`` ``"local"``; ``tolerance`` {ftol, xtol, gtol, max_nfev, stopped_by, status,
        start_from};
        ``n_evaluations`` counts every distinct residual evaluation (scan and start included)."""
    specs = checked_specs(specs)
    bounds = np.array([(s.to_search(s.lower), s.to_search(s.upper)) for s in specs], dtype=float)
    memo = _Memo(_Vector(residuals, specs), workers)
    t0 = time.perf_counter()
    x0, obj_start, start_from = _start(memo, specs, bounds, seed)
    history = [memo.best_cost]
    if progress:
        progress("start", 0.2, {"best": memo.best_cost, "parameters": memo.f.params(memo.best_x)})
    span = bounds[:, 1] - bounds[:, 0]
    x0 = np.clip(x0, bounds[:, 0] + 1e-9 * span, bounds[:, 1] - 1e-9 * span)

    def jac(x: np.ndarray) -> np.ndarray:
        r = memo(x)
        h = np.where(x + rel_step * span <= bounds[:, 1], 1.0, -1.0) * rel_step * span
        cols = memo.batch([x + h[j] * np.eye(len(x))[j] for j in range(len(x))])
        history.append(memo.best_cost)
        if progress:
            progress("local", min(memo.calls / max_nfev, 1.0), {"best": memo.best_cost,
                                                               "parameters": memo.f.params(memo.best_x)})
        return np.column_stack([(c - r) / h[j] for j, c in enumerate(cols)])

    res = least_squares(memo, x0, jac=jac, bounds=(bounds[:, 0], bounds[:, 1]), method="trf",
                        ftol=ftol, xtol=xtol, gtol=gtol, max_nfev=max_nfev, x_scale="jac")
    stopped_by = _TRF_STATUS.get(int(res.status), str(res.status))
    history.append(memo.best_cost)
    if progress:
        progress("done", 1.0, {"best": memo.best_cost, "parameters": memo.f.params(memo.best_x)})
    tolerance = {"ftol": ftol, "xtol": xtol, "gtol": gtol, "max_nfev": max_nfev,
                 "stopped_by": stopped_by, "status": int(res.status), "start_from": start_from}
    message = (f"trust-region least squares (trf) stopped by {stopped_by} "
               f"(ftol {ftol:g}, xtol {xtol:g}, gtol {gtol:g}) after {memo.calls} evaluations")
    return CalibrationResult(memo.f.params(memo.best_x), memo.best_cost, obj_start, memo.calls,
                             int(res.status) > 0, message, history, specs, time.perf_counter() - t0,
                             method="local", tolerance=tolerance)

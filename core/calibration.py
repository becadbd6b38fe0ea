"""Calibration of model parameters: a global genetic-type search plus a local polish, and
modal calibration from identified modes ([ref 3]).

* :func:`calibrate` minimises any scalar objective of named, bounded parameters with
  ``scipy.optimize.differential_evolution`` (Latin-hypercube initial population, as [ref 3]
  initialises its genetic algorithm; small population; seeded; candidates of one generation
  evaluated through an optional ``map``-like executor) followed by a bounded local polish
  (``scipy.optimize.minimize``, Powell — derivative-free, so it tolerates the slightly
  non-smooth objectives of percentile-based EN quantities).
* :func:`railval.core.calibration_local.calibrate_local` fits 1–3 parameters in few
  evaluations by least squares on the residual vector of :func:`validation_residuals`, whose
  squared norm is :func:`validation_objective`.
* :func:`validation_objective` is the scalar form of the DynoTRAIN verdict (docs/design.md §3).
* :func:`calibrate_modal` fits model parameters to identified natural frequencies and mode
  shapes: numerical modes are paired with experimental ones by highest MAC and the objective
  is the sum of squared relative frequency residuals plus MAC residuals ([ref 3] §4), with
  the before/after error table of [ref 3] Fig. 5.
* :func:`coach_vertical_modes` is the rigid-body vertical modal model of the passenger coach
  template (car body bounce/pitch on the secondary suspension, bogies on the primary).

Units: SI throughout (kg, kg·m², N/m, m, Hz).

References
----------
Seed 002 (Freight wagon calibration from operational modal data), §4: parameters m_cb,
I_cb,y, k_1,z; LHS-initialised genetic algorithm; objective = sum of natural frequency and
MAC residuals; pairing by highest MAC; Fig. 5 relative frequency errors before/after.
R. Storn, K. Price, "Differential evolution", J. Global Optimization 11, 341–359, 1997.
S. Iwnicki (ed.), "The Manchester Benchmarks for rail vehicle simulation", Vehicle System
Dynamics 30(3–4), 1998 — vehicle 1 default values used by :data:`COACH_MODAL_DEFAULTS`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.linalg import eigh
from scipy.optimize import differential_evolution, minimize

from railval.core.errors import CalibrationDidNotConverge, InvalidParameter, RailvalError
from railval.core.modal import pair_modes
from railval.core.sim.vehicles import template_parameters

__all__ = [
    "COACH_MODAL_DEFAULTS",
    "COACH_MODAL_PARAMETERS",
    "CalibrationResult",
    "ModalCalibrationResult",
    "ParameterSpec",
    "calibrate",
    "calibrate_modal",
    "coach_modal_base",
    "coach_vertical_modes",
    "modal_objective",
    "validation_objective",
]


@dataclass(frozen=True)
class ParameterSpec:
    """A calibrated parameter: name, bounds [lower, upper] in ``unit``, optional start value.
    ``log``: search log10(value) (stiffness-like parameters spanning decades; needs lower > 0)."""

    name: str
    lower: float
    upper: float
    unit: str = ""
    start: float | None = None
    log: bool = False

    def __post_init__(self) -> None:
        if not (math.isfinite(self.lower) and math.isfinite(self.upper) and self.lower < self.upper):
            raise InvalidParameter(
                f"parameter {self.name}: bounds must be finite with lower < upper, got [{self.lower}, {self.upper}]")
        if self.start is not None and not (self.lower <= self.start <= self.upper):
            raise InvalidParameter(
                f"parameter {self.name}: start {self.start} outside bounds [{self.lower}, {self.upper}]")
        if self.log and not self.lower > 0:
            raise InvalidParameter(f"parameter {self.name}: a log-scale search needs lower > 0, got {self.lower}")

    def to_search(self, value: float) -> float:
        return math.log10(value) if self.log else float(value)

    def from_search(self, x: float) -> float:
        return float(min(max(10.0 ** x if self.log else x, self.lower), self.upper))


Progress = Callable[[str, float, dict[str, Any]], None]


@dataclass
class CalibrationResult:
    """Outcome of :func:`calibrate`.

    ``parameters`` best values; ``objective_start`` objective at the start values (if given),
    ``objective`` at the optimum; ``history`` best objective after every generation then after
    the polish; ``n_evaluations`` objective calls; ``converged`` as reported by the optimiser.
    Services add ``validation``, ``lineage`` and ``configuration`` entries to ``extra``.
    """

    parameters: dict[str, float]
    objective: float
    objective_start: float | None
    n_evaluations: int
    converged: bool
    message: str
    history: list[float] = field(default_factory=list)
    specs: list[ParameterSpec] = field(default_factory=list)
    elapsed_s: float = 0.0
    extra: dict[str, Any] = field(default_factory=dict)
    method: str = "global"
    tolerance: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        out = {
            "parameters": dict(self.parameters),
            "bounds": {s.name: [s.lower, s.upper] for s in self.specs},
            "units": {s.name: s.unit for s in self.specs},
            "log_scale": [s.name for s in self.specs if s.log],
            "objective": self.objective,
            "objective_start": self.objective_start,
            "n_evaluations": self.n_evaluations,
            "converged": self.converged,
            "message": self.message,
            "history": list(self.history),
            "elapsed_s": self.elapsed_s,
            "method": self.method,
            "tolerance": dict(self.tolerance),
        }
        out.update(self.extra)
        return out


class _Counted:
    """Picklable wrapper mapping a unit-cube vector to a named-parameter objective call."""

    def __init__(self, objective: Callable[[dict[str, float]], float], specs: Sequence[ParameterSpec]):
        self.objective = objective
        self.specs = list(specs)

    def params(self, x: np.ndarray) -> dict[str, float]:
        return {s.name: s.from_search(float(v)) for s, v in zip(self.specs, x, strict=True)}

    def __call__(self, x: np.ndarray) -> float:
        value = float(self.objective(self.params(x)))
        return value if math.isfinite(value) else 1e12


class _BudgetSpent(RailvalError):
    """The local polish used its evaluation budget."""


class _Budgeted:
    """``f`` allowed ``maxfev`` calls (then :class:`_BudgetSpent`), remembering the best."""

    def __init__(self, f: Callable[[np.ndarray], float], maxfev: int):
        self.f, self.maxfev, self.calls = f, int(maxfev), 0
        self.best_x: np.ndarray | None = None
        self.best_f = math.inf

    def __call__(self, x: np.ndarray) -> float:
        if self.calls >= self.maxfev:
            raise _BudgetSpent
        self.calls += 1
        value = self.f(x)
        if value < self.best_f:
            self.best_x, self.best_f = np.array(x, float), value
        return value


def checked_specs(specs: Sequence[ParameterSpec]) -> list[ParameterSpec]:
    """``specs`` as a list: at least one parameter, names unique (else :class:`InvalidParameter`)."""
    specs = list(specs)
    if not specs:
        raise InvalidParameter("calibrate needs at least one parameter, got none")
    names = [s.name for s in specs]
    if len(set(names)) != len(names):
        raise InvalidParameter(f"parameter names must be unique, got {names}")
    return specs


def max_evaluations(n_parameters: int, popsize: int, maxiter: int, polish_maxfev: int,
                    start: bool = True) -> int:
    """Upper bound of the objective calls of :func:`calibrate`: the start point, scipy's
    differential evolution population of max(5, ``popsize``·n) members initially and per
    generation for at most ``maxiter`` generations (it may stop earlier at convergence),
    and the polish budget.

    Parameters
    ----------
    n_parameters, popsize, maxiter, polish_maxfev : int
    start : bool
        Whether the start point is evaluated.

    Returns
    -------
    int
    """
    members = max(5, popsize * max(1, n_parameters))
    return int(start) + members * (maxiter + 1) + polish_maxfev


def calibrate(objective: Callable[[dict[str, float]], float], specs: Sequence[ParameterSpec], *,
              seed: int = 0, popsize: int = 6, maxiter: int = 15, tol: float = 1e-3,
              polish: bool = True, polish_maxfev: int = 60, workers: Callable | None = None,
              progress: Progress | None = None, raise_on_failure: bool = False) -> CalibrationResult:
    """Minimise ``objective(params)`` over the bounded box of ``specs``.

    Parameters
    ----------
    objective, specs : callable, sequence of ParameterSpec
        ``{name: value}`` → cost; the bounded parameters (``log=True``: searched as log10).
    seed, popsize, maxiter, tol : int, int, int, float
        Global stage ``differential_evolution`` (best1bin, Latin-hypercube initialisation as
        [ref 3]; ``popsize``·n per generation; start values, when all given, via ``x0``).
    polish, polish_maxfev : bool, int
        Powell polish, same bounds, ≤ ``polish_maxfev`` evaluations (strictly; 0 = none).
    workers, progress : callable or None
        ``map(func, iterable)`` evaluating a generation in parallel (``updating="deferred"``);
        ``progress(stage, fraction, info)`` after every generation and at the end.
    raise_on_failure : bool
        Raise :class:`CalibrationDidNotConverge` when the DE stage did not converge.

    Returns
    -------
    CalibrationResult
        ``n_evaluations`` excludes the start point's call (total bound: :func:`max_evaluations`)."""
    specs = checked_specs(specs)
    f = _Counted(objective, specs)
    bounds = [(s.to_search(s.lower), s.to_search(s.upper)) for s in specs]
    x0 = None
    obj_start = None
    if all(s.start is not None for s in specs):
        x0 = np.array([s.to_search(s.start) for s in specs], dtype=float)
        obj_start = f(x0)
        # a start on a bound can round outside it in scipy's unit-cube check: nudge inwards
        lo, hi = np.array(bounds).T
        x0 = np.clip(x0, lo + 1e-9 * (hi - lo), hi - 1e-9 * (hi - lo))
    history: list[float] = []
    t0 = time.perf_counter()
    gen = [0]

    def cb(intermediate_result) -> None:
        gen[0] += 1
        history.append(float(intermediate_result.fun))
        if progress:
            progress("global", min(gen[0] / maxiter, 1.0),
                     {"generation": gen[0], "best": float(intermediate_result.fun),
                      "parameters": f.params(intermediate_result.x)})

    kwargs: dict[str, Any] = {}
    if workers is not None:
        kwargs.update(workers=workers, updating="deferred")
    res = differential_evolution(f, bounds, seed=seed, popsize=popsize, maxiter=maxiter, tol=tol,
                                 init="latinhypercube", polish=False, x0=x0, callback=cb, **kwargs)
    x_best, f_best, nfev = np.asarray(res.x, float), float(res.fun), int(res.nfev)
    converged, message = bool(res.success), str(res.message)
    if polish and polish_maxfev > 0:
        # Powell checks its maxfev only between line searches; the budget here is strict
        g = _Budgeted(f, polish_maxfev)
        try:
            loc = minimize(g, x_best, method="Powell", bounds=bounds,
                           options={"maxfev": polish_maxfev, "xtol": 1e-3, "ftol": 1e-4})
            x_loc, f_loc = np.asarray(loc.x, float), float(loc.fun)
        except _BudgetSpent:
            x_loc, f_loc = g.best_x, g.best_f
        nfev += g.calls
        if x_loc is not None and f_loc < f_best:
            x_best, f_best = np.clip(x_loc, [b[0] for b in bounds], [b[1] for b in bounds]), f_loc
        history.append(f_best)
    if progress:
        progress("done", 1.0, {"best": f_best, "parameters": f.params(x_best)})
    if raise_on_failure and not converged:
        raise CalibrationDidNotConverge(f"differential evolution stopped after {nfev} evaluations: {message}")
    return CalibrationResult(f.params(x_best), f_best, obj_start, nfev,
                             converged, message, history, specs, time.perf_counter() - t0, method="global",
                             tolerance={"tol": tol, "maxiter": maxiter, "stopped_by": "tol" if converged else "maxiter"})


def validation_objective(mean_norm: Mapping[str, float], std_norm: Mapping[str, float], *,
                         smooth: float = 0.0) -> float:
    """Scalar form of the DynoTRAIN verdict: Σ_q max(|mean_norm_q|, std_norm_q)².

    ``mean_norm``/``std_norm`` are the per-quantity mean and standard deviation of D_v divided
    by their limits (docs/design.md §3, Polach & Böttcher 2014 §5: a quantity passes when both are ≤ 1), so the
    objective is ≤ 12 when every quantity passes and every term is dimensionless. With
    ``smooth`` > 0 the max is replaced by the log-sum-exp soft maximum
    s·ln(e^{|m|/s} + e^{σ/s}) (differentiable; tends to the max as s → 0).

    Parameters
    ----------
    mean_norm, std_norm : mapping of str to float
        Quantity id → normalised mean / standard deviation of D_v (dimensionless).
    smooth : float
        Soft-maximum scale s (0 = the exact maximum).

    Returns
    -------
    float
        Dimensionless objective.

    Examples
    --------
    >>> validation_objective({"Q_max": 0.5}, {"Q_max": 1.0})
    1.0
    """
    total = 0.0
    for q, m in mean_norm.items():
        s = std_norm.get(q, 0.0)
        a, b = abs(float(m)), float(s)
        if not (math.isfinite(a) and math.isfinite(b)):
            continue
        if smooth > 0:
            hi = max(a, b)
            v = hi + smooth * math.log(math.exp((a - hi) / smooth) + math.exp((b - hi) / smooth))
        else:
            v = max(a, b)
        total += v * v
    return total


def validation_residuals(mean_norm: Mapping[str, float], std_norm: Mapping[str, float]) -> np.ndarray:
    """Residual vector of the DynoTRAIN verdict: r_q = max(|mean_norm_q|, std_norm_q), one entry
    per quantity in ``mean_norm`` order (non-finite entries → 0, as :func:`validation_objective`
    skips them), so that Σ r_q² is exactly :func:`validation_objective` (docs/design.md §3,
    Polach & Böttcher 2014 §5: a quantity passes when both normalised values are ≤ 1).

    Examples
    --------
    >>> validation_residuals({"Q_max": 0.5, "Y_max": -2.0}, {"Q_max": 1.0, "Y_max": 0.1}).tolist()
    [1.0, 2.0]
    """
    out = []
    for q, m in mean_norm.items():
        a, b = abs(float(m)), float(std_norm.get(q, 0.0))
        out.append(max(a, b) if math.isfinite(a) and math.isfinite(b) else 0.0)
    return np.asarray(out, dtype=float)


# --------------------------------------------------------------------------- modal calibration
#: Vertical rigid-body parameters of the passenger coach template (Manchester Benchmark vehicle
#: 1, docs/design.md §6): masses kg, inertia kg·m², stiffness per suspension position N/m, lengths m.
COACH_MODAL_DEFAULTS: dict[str, float] = {
    "m_carbody": 32000.0,
    "I_pitch_carbody": 1.97e6,
    "k_secondary_z": 430e3,
    "k_primary_z": 1.2e6,
    "m_bogie": 2615.0,
    "bogie_half_distance": 9.5,
}

#: Calibratable modal parameters: default bounds (± 30 % around the defaults) and units.
COACH_MODAL_PARAMETERS: dict[str, tuple[float, float, str]] = {
    "m_carbody": (22400.0, 41600.0, "kg"),
    "I_pitch_carbody": (1.379e6, 2.561e6, "kg·m²"),
    "k_secondary_z": (301e3, 559e3, "N/m"),
    "k_primary_z": (0.84e6, 1.56e6, "N/m"),
    "m_bogie": (1830.0, 3400.0, "kg"),
}


def coach_vertical_modes(params: Mapping[str, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Undamped vertical modes of the coach: DOFs car body bounce z_c, pitch θ_c, bogie
    bounces z_b1 (leading, x = +a), z_b2 (x = −a).

    Potential energy Σ_{j=1,2} [k_s,b (z_bj − z_c ∓ a θ_c)² + k_p,b z_bj²]/2 with per-bogie
    stiffnesses k_s,b = 2·k_secondary_z (two secondary positions) and k_p,b = 4·k_primary_z
    (four axle boxes); M = diag(m_c, I_c, m_b, m_b). Solved by ``scipy.linalg.eigh`` (K, M).
    Returns (frequencies in Hz ascending, shapes at the car body sensors above bogie 1 and 2 —
    z_c ± a θ_c — as a (2, 4) array). Closed-form check (bogies rigidly fixed,
    k_p → ∞): bounce f = √(2k_s,b/m_c)/2π, pitch f = √(2k_s,b a²/I_c)/2π.

    Parameters
    ----------
    params : mapping of str to float or None
        :data:`COACH_MODAL_DEFAULTS` overrides (SI units: kg, kg·m², N/m, m).

    Returns
    -------
    tuple of numpy.ndarray
        Frequencies in Hz, shape (4,); shapes, shape (2, 4).
    """
    p = dict(COACH_MODAL_DEFAULTS)
    if params:
        unknown = set(params) - set(p)
        if unknown:
            raise InvalidParameter(f"unknown coach modal parameter(s) {sorted(unknown)}; known: {sorted(p)}")
        p.update({k: float(v) for k, v in params.items()})
    for k, v in p.items():
        if not v > 0:
            raise InvalidParameter(f"coach modal parameter {k} must be > 0, got {v}")
    a = p["bogie_half_distance"]
    ks, kp = 2.0 * p["k_secondary_z"], 4.0 * p["k_primary_z"]
    M = np.diag([p["m_carbody"], p["I_pitch_carbody"], p["m_bogie"], p["m_bogie"]])
    K = np.array([
        [2 * ks, 0.0, -ks, -ks],
        [0.0, 2 * ks * a * a, -ks * a, ks * a],
        [-ks, -ks * a, ks + kp, 0.0],
        [-ks, ks * a, 0.0, ks + kp],
    ])
    w2, V = eigh(K, M)
    sensors = np.array([[1.0, a, 0.0, 0.0], [1.0, -a, 0.0, 0.0]])
    return np.sqrt(np.maximum(w2, 0.0)) / (2 * np.pi), sensors @ V


def modal_objective(freq_model: np.ndarray, shapes_model: np.ndarray, freq_exp: np.ndarray,
                    shapes_exp: np.ndarray, *, mac_weight: float = 1.0,
                    freq_weight_pairing: float = 0.5) -> tuple[float, list[tuple[int, int, float]]]:
    """Seed 002 §4 objective: pair every experimental mode with a model mode by highest MAC
    (ties broken by frequency, :func:`railval.core.modal.pair_modes`), then
    J = Σ_i ((f_model − f_exp)/f_exp)² + mac_weight · Σ_i (1 − MAC_i). Dimensionless.
    Returns (J, pairs ``(i_exp, j_model, mac)``).

    Parameters
    ----------
    freq_model, freq_exp : numpy.ndarray
        Natural frequencies in Hz, shapes (m_model,) and (m_exp,).
    shapes_model, shapes_exp : numpy.ndarray
        Mode shapes as columns at the same sensors, shapes (n_sensors, m_model/m_exp).
    mac_weight, freq_weight_pairing : float
        Weight of the MAC term and of the frequency tie-break in the pairing.

    Returns
    -------
    tuple of (float, list of tuple of (int, int, float))
    """
    pairs = pair_modes(freq_exp, shapes_exp, freq_model, shapes_model, freq_weight=freq_weight_pairing)
    J = 0.0
    for i, j, m in pairs:
        J += ((freq_model[j] - freq_exp[i]) / freq_exp[i]) ** 2 + mac_weight * (1.0 - m)
    return float(J), pairs


@dataclass
class ModalCalibrationResult:
    """Seed 002 Fig. 5 as a table: per experimental mode the frequency, the paired model
    frequency and relative error (%) and MAC before and after calibration; plus the fitted
    parameters (:class:`CalibrationResult`)."""

    rows: list[dict[str, float]]
    calibration: CalibrationResult
    parameters_before: dict[str, float]

    @property
    def mean_abs_error_before_pct(self) -> float:
        return float(np.mean([abs(r["error_before_pct"]) for r in self.rows]))

    @property
    def mean_abs_error_after_pct(self) -> float:
        return float(np.mean([abs(r["error_after_pct"]) for r in self.rows]))

    def to_dict(self) -> dict[str, Any]:
        return {"modes": list(self.rows), "parameters_before": dict(self.parameters_before),
                "parameters_after": dict(self.calibration.parameters),
                "mean_abs_error_before_pct": self.mean_abs_error_before_pct,
                "mean_abs_error_after_pct": self.mean_abs_error_after_pct,
                "calibration": self.calibration.to_dict()}

    def to_pandas(self):
        import pandas as pd

        return pd.DataFrame(self.rows)


class _ModalFit:
    def __init__(self, model, base, freq_exp, shapes_exp, mac_weight):
        self.model, self.base = model, dict(base)
        self.freq_exp, self.shapes_exp, self.mac_weight = freq_exp, shapes_exp, mac_weight

    def __call__(self, params: dict[str, float]) -> float:
        f, s = self.model({**self.base, **params})
        return modal_objective(f, s, self.freq_exp, self.shapes_exp, mac_weight=self.mac_weight)[0]


def calibrate_modal(freq_exp: Sequence[float], shapes_exp: np.ndarray, specs: Sequence[ParameterSpec], *,
                    model: Callable[[Mapping[str, float]], tuple[np.ndarray, np.ndarray]] = coach_vertical_modes,
                    base: Mapping[str, float] | None = None, mac_weight: float = 1.0, seed: int = 0,
                    popsize: int = 10, maxiter: int = 60, progress: Progress | None = None) -> ModalCalibrationResult:
    """Fit ``specs`` of ``model`` to identified modes ([ref 3] §4; objective
    :func:`modal_objective`). ``base``: values of the parameters not calibrated (and the
    starting point). Only parameters that move at least one identified mode can be identified
    ([ref 3]: "only those sufficiently correlated parameters can be estimated accurately");
    with two car body modes choose at most two parameters, e.g. I_pitch_carbody and
    k_secondary_z with the mass fixed from the static wheel load.

    Parameters
    ----------
    freq_exp : sequence of float
        Identified natural frequencies in Hz, shape (m_exp,).
    shapes_exp : numpy.ndarray
        Identified shapes as columns, shape (n_sensors, m_exp).
    specs : sequence of ParameterSpec
        Parameters to fit, with their bounds.
    model : callable
        Parameter values → (frequencies in Hz, shapes) as :func:`coach_vertical_modes`.
    base : mapping of str to float or None
    mac_weight : float
    seed, popsize, maxiter : int
        Differential evolution settings (:func:`calibrate`).
    progress : Progress or None
        Called with the progress of the search.

    Returns
    -------
    ModalCalibrationResult
        Per-mode rows before/after, the calibration result and the starting objective.
    """
    freq_exp = np.asarray(freq_exp, float)
    shapes_exp = np.atleast_2d(np.asarray(shapes_exp))
    if shapes_exp.shape[1] != freq_exp.size:
        raise InvalidParameter(
            f"shapes_exp must have one column per frequency ({freq_exp.size}), got {shapes_exp.shape[1]}")
    base = dict(base or {})
    specs = [ParameterSpec(s.name, s.lower, s.upper, s.unit,
                           s.start if s.start is not None else
                           min(max(base.get(s.name, COACH_MODAL_DEFAULTS.get(s.name, (s.lower + s.upper) / 2)),
                                   s.lower), s.upper)) for s in specs]
    before = {**base, **{s.name: float(s.start) for s in specs}}
    fit = _ModalFit(model, base, freq_exp, shapes_exp, mac_weight)
    cal = calibrate(fit, specs, seed=seed, popsize=popsize, maxiter=maxiter, tol=1e-8, progress=progress)
    rows = []
    f0, s0 = model(before)
    f1, s1 = model({**base, **cal.parameters})
    _, p0 = modal_objective(f0, s0, freq_exp, shapes_exp)
    _, p1 = modal_objective(f1, s1, freq_exp, shapes_exp)
    for (i, j0, m0), (_, j1, m1) in zip(p0, p1, strict=True):
        rows.append({"mode": i + 1, "freq_exp_hz": float(freq_exp[i]),
                     "freq_before_hz": float(f0[j0]), "error_before_pct": float(100 * (f0[j0] - freq_exp[i]) / freq_exp[i]),
                     "mac_before": m0,
                     "freq_after_hz": float(f1[j1]), "error_after_pct": float(100 * (f1[j1] - freq_exp[i]) / freq_exp[i]),
                     "mac_after": m1})
    return ModalCalibrationResult(rows, cal, before)


def coach_modal_base(vehicle_parameters: Mapping[str, Any]) -> dict[str, float]:
    """Coach modal model values (:data:`COACH_MODAL_DEFAULTS` names) from the simulator's coach
    template defaults (:func:`railval.core.sim.vehicles.template_parameters`) overlaid by a
    campaign's numeric vehicle parameters; ``bogie_centres`` gives ``bogie_half_distance``.

    Parameters
    ----------
    vehicle_parameters : mapping of str to Any
        A campaign's vehicle parameters (non-numeric ones ignored).

    Returns
    -------
    dict of str to float
    """
    merged = {p.name: float(p.default) for p in template_parameters("coach")}
    merged.update({k: float(v) for k, v in vehicle_parameters.items() if isinstance(v, (int, float))})
    base = {k: merged[k] for k in COACH_MODAL_DEFAULTS if k in merged}
    if "bogie_centres" in merged:
        base["bogie_half_distance"] = merged["bogie_centres"] / 2.0
    return base

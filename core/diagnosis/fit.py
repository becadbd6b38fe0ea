"""Candidate causes and the fit along one parameter (docs/design.md §7, docs/diagnosis.md).

For a candidate e (an effect the configuration lacks, or one model parameter) the caller
simulates the configuration with e at a few values v of one parameter (all others at their
defaults) over the campaign's sections. The pattern P_e(v) is interpolated linearly in v (or
in log v) between the simulated values — for a model parameter a linearised sensitivity from
one perturbed simulation, extrapolated over its search bounds — and v* minimises the
weighted remaining residual ‖P_e(v)‖²_W over the range. The minimum on each linear segment is
a quadratic in the segment parameter, solved in closed form (:func:`_min_cost`); the explained
share is ``1 − ‖P_e(v*)‖²_W / ‖r‖²_W`` (r the configuration's own pattern).

References: docs/design.md §7 (this procedure); parameter names, units, defaults and bounds
from the template registry :mod:`railval.core.sim.vehicles`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from railval.core.diagnosis.evidence import SectionEvidence
from railval.core.errors import InvalidParameter

#: Vehicle-template parameters tried as candidate causes beside the effects (masses, inertias,
#: stiffnesses and dampings per direction: primary, secondary, yaw dampers). Each entry
#: ``name: (step, low, high)``: ``step`` is the factor of the one perturbed simulation of the
#: linearised sensitivity (stiffness/damping ×0.5 — worn or soft components are the frequent
#: error; masses/inertias ×1.2), ``low``–``high`` the search box as factors of the model's
#: value (log scale, clipped to the template bounds). Names, units, defaults and bounds come
#: from the template registry :mod:`railval.core.sim.vehicles`.
_KC = (0.5, 0.1, 4.0)
_MI = (1.2, 0.5, 2.0)
PARAMETER_CANDIDATES: dict[str, dict[str, tuple[float, float, float]]] = {
    "coach": {"m_carbody": _MI, "I_pitch_carbody": _MI, "I_yaw_carbody": _MI, "m_bogie": _MI,
              "k_primary_x": _KC, "k_primary_y": _KC, "k_primary_z": _KC, "c_primary_z": _KC,
              "k_secondary_y": _KC, "k_secondary_z": _KC, "c_secondary_y": _KC, "c_secondary_z": _KC,
              "c_yaw_damper": _KC},
    "wagon": {"m_body_tare": _MI, "payload": _MI, "k_leaf_z": _KC, "leaf_friction": _KC,
              "link_length": _KC, "link_friction": _KC},
}

#: Parameter candidates acting on the wheel–rail interface: the wheelset's longitudinal and
#: lateral guidance stiffness sets, with the creep forces, how the wheelsets steer in curves —
#: the guiding forces a contact difference changes too (docs/diagnosis.md "Interface
#: candidates"; the effects say it in :attr:`railval.core.sim.effects.Effect.interface`).
INTERFACE_PARAMETERS = frozenset({"k_primary_x", "k_primary_y", "link_length"})

#: The mass and inertia candidates (those perturbed by the ``_MI`` step): a mass does not wear,
#: so it is a cause only where identified (docs/diagnosis.md "Interface candidates").
MASS_PARAMETERS = frozenset(n for t in PARAMETER_CANDIDATES.values() for n, v in t.items() if v is _MI)


@dataclass
class CandidateFamily:
    """A candidate cause and its simulated evidence along one parameter.

    ``kind`` ``"effect"`` (``name`` = effect id; ``values`` the scanned values of
    ``parameter``, the others at ``defaults``) or ``"parameter"`` (``name`` = ``model.PARAM``;
    ``values`` = the model's value ``reference`` and one perturbed value: a linearised
    sensitivity, extrapolated linearly in log(value) over ``bounds``). ``evidence[k]`` belongs
    to ``values[k]``. ``plausible``: physically plausible range (``plausible_source`` cites it).
    """

    kind: str
    name: str
    parameter: str
    values: list[float]
    evidence: list[SectionEvidence]
    bounds: tuple[float, float]
    log: bool = False
    extrapolate: bool = False
    defaults: dict[str, float] = field(default_factory=dict)
    reference: float | None = None
    plausible: tuple[float, float] | None = None
    plausible_source: str = ""
    unit: str = ""
    title: str = ""
    explanation: str = ""
    #: acts on the wheel–rail interface (effect registry ``Effect.interface`` or
    #: :data:`INTERFACE_PARAMETERS`): needs support outside the guiding forces to be a cause
    interface: bool = False
    #: evidence standing in for a screened-out candidate (core/diagnosis/screen.py ``stand_in``):
    #: counted in the noise floor, never ranked
    floor_only: bool = False


def _u(v: np.ndarray | float, log: bool):
    return np.log(v) if log else v


class _Curve:
    """Piecewise-linear pattern curve of a family along u = value or log(value) (with linear
    extrapolation beyond the simulated values when the family asks for it)."""

    def __init__(self, fam: CandidateFamily, n_fine: int = 201):
        order = np.argsort(fam.values)
        self.v = np.asarray(fam.values, float)[order]
        self.order = order
        self.log = fam.log
        u = _u(self.v, fam.log)
        if u.size < 2 or np.any(np.diff(u) <= 0):
            raise InvalidParameter(f"candidate {fam.name}: needs ≥ 2 distinct simulated values, got {fam.values}")
        lo, hi = (fam.bounds if fam.extrapolate else (self.v[0], self.v[-1]))
        self.range = (float(lo), float(hi))
        self.fine = np.linspace(float(_u(lo, fam.log)), float(_u(hi, fam.log)), n_fine)
        idx = np.clip(np.searchsorted(u, self.fine, side="right") - 1, 0, u.size - 2)
        self.idx = idx
        self.t = (self.fine - u[idx]) / (u[idx + 1] - u[idx])
        self.u = u

    def patterns(self, P: np.ndarray) -> np.ndarray:
        """Fine-grid patterns (F, n) from the simulated ones ``P`` (K, n) in family order."""
        P = P[self.order]
        return P[self.idx] * (1 - self.t)[:, None] + P[self.idx + 1] * self.t[:, None]

    def pattern_at(self, P: np.ndarray, k: int) -> np.ndarray:
        """Row ``k`` of :meth:`patterns` alone (the same values)."""
        P = P[self.order]
        i, t = self.idx[k], self.t[k]
        return P[i] * (1 - t) + P[i + 1] * t

    def values_at(self, u: np.ndarray) -> np.ndarray:
        """Parameter values of points ``u`` on the curve's axis, clipped to the range."""
        vals = np.exp(u) if self.log else u
        return np.clip(vals, self.range[0], self.range[1])

    def value(self, k: int) -> float:
        """The value at fine-grid point ``k``: the range's ends exactly at the ends, inside the
        range elsewhere (exp(log(bound)) may round past the bound by one ulp, which a later
        simulation would refuse)."""
        if k in (0, self.fine.size - 1, -1):
            return self.range[0] if k == 0 else self.range[1]
        x = float(self.fine[k])
        return float(min(max(float(np.exp(x)) if self.log else x, self.range[0]), self.range[1]))


def _min_cost(curve: _Curve, P: np.ndarray, w: np.ndarray, argmin: bool = False):
    """min over the curve's range of ‖w·P(u)‖² for many node sets at once: ``P`` (B, K, n) in
    family order → (B,). Exact on each linear segment (a quadratic in the segment parameter,
    minimised in closed form and clipped to the segment; the first and last segments extend
    to the ends of the range when the family extrapolates). ``argmin=True``: also the values
    (in the parameter's unit, inside the range) where the minima lie."""
    X = P[:, curve.order, :] * w
    rows = X.shape[0]
    best, where = _min_cost_rows(X, np.broadcast_to(curve.u, (rows, curve.u.size)),
                                 np.full(rows, float(curve.fine[0])), np.full(rows, float(curve.fine[-1])))
    if not argmin:
        return best
    return best, curve.values_at(where)


def _min_cost_rows(X: np.ndarray, U: np.ndarray, lo_end: np.ndarray, hi_end: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_min_cost` of node sets of many curves at once, one curve per row: ``X`` (R, K, n)
    weighted nodes in each curve's order, ``U`` (R, K) its u nodes, ``lo_end``/``hi_end`` (R,)
    the ends of its range in u → (minimum cost, u where it lies). Every row is computed with the
    same floating-point operations as one curve alone (row-wise elementwise operations and sums
    over the last axis), so rows of several candidates stacked give bit-identical results."""
    R, K = X.shape[0], X.shape[1]
    best = np.full(R, np.inf)
    where = np.array(lo_end, float, copy=True)
    zero, one = np.zeros(R), np.ones(R)
    for j in range(K - 1):
        du = U[:, j + 1] - U[:, j]
        t_lo = (lo_end - U[:, j]) / du if j == 0 else zero
        t_hi = (hi_end - U[:, j]) / du if j == K - 2 else one
        live = ~(t_hi < t_lo)
        a, d = X[:, j, :], X[:, j + 1, :] - X[:, j, :]
        dd = np.sum(d * d, axis=1)
        ad = np.sum(a * d, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(dd > 0, -ad / dd, t_lo)
        t = np.clip(t, t_lo, t_hi)
        cost = np.sum((a + t[:, None] * d) ** 2, axis=1)
        better = (cost < best) & live
        where = np.where(better, U[:, j] + t * du, where)
        best = np.where(live, np.minimum(best, cost), best)
    return best, where


def _fit(curve: _Curve, P: np.ndarray, w: np.ndarray) -> tuple[int, float, np.ndarray]:
    k, costs, Pk = _fit_costs(curve, P, w)
    return k, float(costs[k]), Pk


def _fit_costs(curve: _Curve, P: np.ndarray, w: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
    """The fine-grid fit: best index, the cost at every fine-grid point, the best pattern."""
    Pf = curve.patterns(P)
    cost = np.sum((Pf * w) ** 2, axis=1)
    k = int(np.argmin(cost))
    return k, cost, Pf[k]


def _fit_folds(curve: _Curve, P: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The fine-grid index of the best fit of several node sets ``P`` (F, K, n) at once (the
    training sections of every fold): the same values as :func:`_fit` on each."""
    P = P[:, curve.order]
    t = curve.t[None, :, None]
    Pf = P[:, curve.idx] * (1 - curve.t)[None, :, None] + P[:, curve.idx + 1] * t
    return np.argmin(np.sum((Pf * w) ** 2, axis=2), axis=1)


def scan_values(lower: float, upper: float, default: float, n: int, log: bool = False) -> list[float]:
    """The values of one effect parameter a diagnosis simulates (docs/design.md §7): ``n``
    values spanning [lower, upper] (equally spaced, or geometrically with ``log``) plus the
    default, sorted, unique."""
    grid = np.geomspace(lower, upper, n) if log else np.linspace(lower, upper, n)
    return sorted(set(grid.tolist()) | {float(default)})

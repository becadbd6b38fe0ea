"""Per-section evidence of a diagnosis and the resamplings of the sections (docs/diagnosis.md):
the pattern of any subset or weighting of a campaign's sections without new simulation,
k-fold splits and a bootstrap, both stratified by EN 14363 test zone.

References: Efron & Tibshirani 1993 §8.2 (stratified bootstrap); Hastie, Tibshirani &
Friedman 2009 §7.10 (k-fold cross-validation); EN 14363:2016 §7.6 (test zones).
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from railval.core.diagnosis.patterns import DEFAULT_BANDS_HZ, Component, Pattern


@dataclass
class SectionEvidence:
    """Per-section contributions of one simulated model to the residual pattern, so that the
    pattern of any subset or resample of the sections is a weighted sum (held-out folds and
    the bootstrap need no new simulation).

    ``sums[s, j]``/``counts[s, j]``: sum and number of the normalised differences D_v/limit of
    section s in quantity × zone × position component j (the first ``n_pair`` labels);
    ``sim_power``/``meas_power[s, j]``: band power of section s in band component j (the
    remaining labels). :meth:`values` with section weights w gives
    Σ_s w_s·sums / Σ_s w_s·counts and log₂(Σ_s w_s·P_sim / Σ_s w_s·P_meas) — with all weights 1
    exactly :func:`pattern_from_pairs` + :func:`band_ratio_pattern` of the whole campaign.
    Components without data under the weights are 0 (nothing to explain).
    """

    sections: list[str]
    zones: list[int]
    labels: list[str]
    groups: list[str]
    n_pair: int
    sums: np.ndarray
    counts: np.ndarray
    sim_power: np.ndarray
    meas_power: np.ndarray
    components: list[Component] | None = None
    _memo: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def values(self, weights: np.ndarray | None = None) -> np.ndarray:
        """Pattern values for section weights (shape (S,) → (n,), or (B, S) → (B, n)), read-only.
        Remembered per weights (a diagnosis asks the same evidence — the reference
        simulation shared by many candidates — for the same folds and resamples again)."""
        w = np.ones(len(self.sections)) if weights is None else np.asarray(weights, float)
        key = (w.shape, w.tobytes())
        if key not in self._memo:
            self._memo[key] = self._values(w)
            self._memo[key].flags.writeable = False
        return self._memo[key]

    def _values(self, w: np.ndarray) -> np.ndarray:
        W = np.atleast_2d(w)
        s, c = W @ self.sums, W @ self.counts
        pv = np.divide(s, c, out=np.zeros_like(s), where=c > 0)
        a, b = W @ self.sim_power, W @ self.meas_power
        ok = (a > 0) & (b > 0)
        bv = np.zeros_like(a)
        bv[ok] = np.log2(a[ok] / b[ok])
        out = np.concatenate([pv, bv], axis=1)
        return out[0] if w.ndim == 1 else out

    def pattern(self, weights: np.ndarray | None = None) -> Pattern:
        comps = None if self.components is None else list(self.components)
        return Pattern(list(self.labels), list(self.groups), self.values(weights), comps)


def section_evidence(pairs: Iterable[Mapping[str, Any]], sim_bands: Mapping[str, Mapping[str, np.ndarray]],
                     meas_bands: Mapping[str, Mapping[str, np.ndarray]], sections: Sequence[tuple[str, int]], *,
                     bands: Sequence[tuple[float, float]] = DEFAULT_BANDS_HZ, value_key: str = "norm",
                     like: SectionEvidence | None = None) -> SectionEvidence:
    """Build :class:`SectionEvidence` from validation pairs (records with ``section``,
    ``quantity``, ``zone``, ``position`` and ``value_key``) and per-section band powers
    (``sim_bands[section][channel]`` = powers per band, e.g. :func:`band_powers`).
    ``sections``: ``(id, zone)`` of every section. ``like``: reuse its component layout (what
    it lacks is dropped, what this one lacks has no data) so that evidences of several
    simulations are comparable component by component."""
    sids = [s for s, _ in sections]
    row = {s: k for k, s in enumerate(sids)}
    recs = []
    for r in pairs:
        v = float(r[value_key])
        if math.isfinite(v) and str(r["section"]) in row:
            recs.append((row[str(r["section"])], (str(r["quantity"]), int(r["zone"]), str(r["position"])), v))
    if like is None:
        keys = sorted({k for _, k, _ in recs})
        chans = sorted({c for d in sim_bands.values() for c in d} & {c for d in meas_bands.values() for c in d})
        comps = ([Component.pair(q, z, p) for q, z, p in keys]
                 + [Component.psd(ch, band) for ch in chans for band in bands])
        labels, groups, n_pair = [c.label for c in comps], [c.group for c in comps], len(keys)
    else:
        labels, groups, n_pair = list(like.labels), list(like.groups), like.n_pair
        comps = None if like.components is None else list(like.components)
    sums, counts = _pair_sums(recs, {lab: j for j, lab in enumerate(labels[:n_pair])}, len(sids), n_pair)
    nb = len(labels) - n_pair
    sim_p, meas_p = np.zeros((len(sids), nb)), np.zeros((len(sids), nb))
    bcol = {lab: j for j, lab in enumerate(labels[n_pair:])}
    for src, dst in ((sim_bands, sim_p), (meas_bands, meas_p)):
        for sid, chans in src.items():
            if sid not in row:
                continue
            for ch, powers in chans.items():
                for (lo, hi), x in zip(bands, np.atleast_1d(powers), strict=True):
                    j = bcol.get(f"psd {ch} {lo:g}-{hi:g} Hz")
                    if j is not None:
                        dst[row[sid], j] = float(x)
    return SectionEvidence(sids, [int(z) for _, z in sections], labels, groups, n_pair, sums, counts, sim_p, meas_p,
                           comps)


def _pair_sums(recs: Sequence[tuple[int, tuple[str, int, str], float]], col: Mapping[str, int], n_sec: int,
               n_pair: int) -> tuple[np.ndarray, np.ndarray]:
    """Sum and count of the values per (section row, component column), each component's label
    formatted once; ``np.add.at`` adds in record order, so the sums equal the loop's ``+=``."""
    cols: dict[tuple[str, int, str], int] = {}
    keep = []
    for i, key, v in recs:
        j = cols.get(key)
        if j is None:
            j = cols[key] = col.get(f"{key[0]} zone {key[1]} {key[2]}", -1)
        if j >= 0:
            keep.append((i, j, v))
    sums, counts = np.zeros((n_sec, n_pair)), np.zeros((n_sec, n_pair))
    if keep:
        i, j, v = (np.array(x) for x in zip(*keep, strict=True))
        np.add.at(sums, (i, j), v.astype(float))
        np.add.at(counts, (i, j), 1.0)
    return sums, counts


def zone_folds(zones: Sequence[int], k: int = 3) -> list[np.ndarray]:
    """Test masks of a k-fold split over sections stratified by zone: the sections of every
    zone are dealt round-robin to the folds, so that every zone with ≥ 2 sections lies on both
    sides of each split (k = min(k, largest zone count); folds without sections dropped)."""
    zones = list(zones)
    by_zone: dict[int, list[int]] = defaultdict(list)
    for i, z in enumerate(zones):
        by_zone[z].append(i)
    k = max(2, min(k, max(len(v) for v in by_zone.values()))) if zones else 2
    masks = [np.zeros(len(zones)) for _ in range(k)]
    offset = 0
    for z in sorted(by_zone):
        for j, i in enumerate(by_zone[z]):
            masks[(j + offset) % k][i] = 1.0
        offset += len(by_zone[z])
    return [m for m in masks if m.sum() > 0 and m.sum() < len(zones)]


def zone_bootstrap(zones: Sequence[int], n_boot: int, seed: int = 0) -> np.ndarray:
    """Section weights (n_boot, S) of a bootstrap stratified by zone: within each zone its
    sections are drawn with replacement (Efron & Tibshirani 1993 §8.2, stratified resampling),
    so every resample keeps every zone."""
    rng = np.random.default_rng(seed)
    zones = np.asarray(list(zones))
    W = np.zeros((n_boot, zones.size))
    for z in np.unique(zones):
        idx = np.flatnonzero(zones == z)
        draws = rng.integers(0, idx.size, size=(n_boot, idx.size))
        for b in range(n_boot):
            np.add.at(W[b], idx[draws[b]], 1.0)
    return W

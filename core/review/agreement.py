"""Proportions and inter-rater agreement for Yes/No review answers (docs/workshops.md).

Every statistic here is written from its paper and checked in tests/test_review_stats.py
against a well-kept library or a hand-computed example:

* :func:`wilson_interval` — Wilson (1927), against ``statsmodels`` ``proportion_confint``;
* :func:`fleiss_kappa` — Fleiss (1971), against ``statsmodels.stats.inter_rater.fleiss_kappa``;
* :func:`krippendorff_alpha_nominal` — Krippendorff (2011), against the ``krippendorff`` package;
* :func:`gwet_ac1`, :func:`gwet_ac1_two_raters` — Gwet (2008), against a worked example;
* :func:`mcnemar_exact` — McNemar (1947), exact binomial form, against a hand-computed sum.

The ``*_counts`` helpers take a units × categories table of counts and a matrix of unit
weights (one row per bootstrap replicate, a unit's weight being how often it was drawn), so
that :mod:`railval.core.review.analysis` evaluates a statistic for all bootstrap replicates
in one vectorised pass. A weight row of ones gives the plain statistic.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.stats

from railval.core.errors import InvalidParameter

__all__ = [
    "counts_table",
    "fleiss_kappa",
    "gwet_ac1",
    "gwet_ac1_two_raters",
    "krippendorff_alpha_nominal",
    "mcnemar_exact",
    "wilson_interval",
]


def wilson_interval(successes, n, *, confidence: float = 0.95):
    """Wilson score interval of a binomial proportion (Wilson 1927, "Probable inference, the
    law of succession, and statistical inference", JASA 22:209–212; as written in Brown, Cai
    & DasGupta 2001, Statistical Science 16:101–133):

    ``centre = (p̂ + z²/2n) / (1 + z²/n)``,
    ``half = z / (1 + z²/n) · sqrt(p̂(1 − p̂)/n + z²/4n²)``, ``z = Φ⁻¹(1 − (1 − confidence)/2)``.

    ``successes`` and ``n`` may be scalars or arrays; returns ``(low, high)`` of the same
    shape. ``n`` must be ≥ 1 and ``0 ≤ successes ≤ n``.

    Parameters
    ----------
    successes : int or array_like
        Number of successes (Yes answers).
    n : int or array_like
        Number of trials (answers), ≥ 1.
    confidence : float
        Coverage of the interval, in (0, 1).

    Returns
    -------
    tuple of (float, float) or of ndarray
        ``(low, high)``, clipped to [0, 1].

    Examples
    --------
    >>> low, high = wilson_interval(8, 10)
    >>> round(low, 3), round(high, 3)
    (0.49, 0.943)
    """
    k = np.asarray(successes, dtype=float)
    m = np.asarray(n, dtype=float)
    if not 0.0 < confidence < 1.0:
        raise InvalidParameter(f"confidence: must lie in (0, 1), got {confidence!r}")
    if np.any(m < 1) or np.any(k < 0) or np.any(k > m):
        raise InvalidParameter(
            f"wilson_interval: need n ≥ 1 and 0 ≤ successes ≤ n, got successes={successes!r}, n={n!r}")
    z = scipy.stats.norm.ppf(1.0 - (1.0 - confidence) / 2.0)
    p = k / m
    denom = 1.0 + z * z / m
    centre = (p + z * z / (2.0 * m)) / denom
    half = z / denom * np.sqrt(p * (1.0 - p) / m + z * z / (4.0 * m * m))
    low, high = np.clip(centre - half, 0.0, 1.0), np.clip(centre + half, 0.0, 1.0)
    if low.ndim == 0:
        return float(low), float(high)
    return low, high


# --------------------------------------------------------------------------- tables
def counts_table(data, categories: Sequence | None = None) -> tuple[np.ndarray, list]:
    """Units × categories table of counts from reliability data ``data`` (raters × units,
    ``NaN`` = no answer; the layout of the ``krippendorff`` package). ``categories``
    defaults to the sorted distinct values present. Returns ``(counts, categories)``.

    Parameters
    ----------
    data : array_like
        Raters × units answers, ``NaN`` = no answer.
    categories : sequence, optional
        The answer scale.

    Returns
    -------
    tuple of (ndarray, list)
        Units × categories counts and the categories.
    """
    arr = np.asarray(data, dtype=float)
    if arr.ndim != 2:
        raise InvalidParameter(f"reliability data: must be 2-D (raters × units), got shape {arr.shape}")
    present = np.unique(arr[~np.isnan(arr)])
    cats = sorted(present.tolist()) if categories is None else [float(c) for c in categories]
    unknown = sorted(set(present.tolist()) - set(cats))
    if unknown:
        raise InvalidParameter(f"reliability data: values {unknown} are not among the categories {cats}")
    counts = np.stack([(arr == c).sum(axis=0) for c in cats], axis=1).astype(float) if cats else (
        np.zeros((arr.shape[1], 0)))
    return counts, cats


def _weights(weights, n_units: int) -> np.ndarray:
    if weights is None:
        return np.ones((1, n_units))
    w = np.asarray(weights, dtype=float)
    return w.reshape(1, -1) if w.ndim == 1 else w


def _ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        out = num / den
    out[~np.isfinite(out)] = np.nan
    return out


# --------------------------------------------------------------------------- Fleiss κ
def fleiss_kappa_counts(counts: np.ndarray, weights=None) -> np.ndarray:
    """Fleiss κ of a subjects × categories count table with the same number ``n`` of raters
    for every subject (Fleiss 1971, "Measuring nominal scale agreement among many raters",
    Psychological Bulletin 76:378–382):

    ``P_i = (Σ_j n_ij² − n) / (n(n − 1))``, ``P̄ = mean_i P_i``,
    ``p_j = Σ_i n_ij / (N n)``, ``P̄_e = Σ_j p_j²``, ``κ = (P̄ − P̄_e) / (1 − P̄_e)``.

    ``weights`` (replicates × subjects) turns the means into weighted means; returns one κ
    per replicate (``NaN`` where ``P̄_e = 1``, i.e. every answer in one category).

    Parameters
    ----------
    counts : ndarray
        Subjects × categories counts, equal row sums.
    weights : ndarray, optional
        Replicates × subjects weights (bootstrap multiplicities).

    Returns
    -------
    ndarray
        κ per replicate (one value without ``weights``).
    """
    c = np.asarray(counts, dtype=float)
    w = _weights(weights, c.shape[0])
    n = c.sum(axis=1)
    p_i = ((c * c).sum(axis=1) - n) / (n * (n - 1.0))
    wsum = w.sum(axis=1)
    p_bar = w @ p_i / wsum
    p_j = (w @ c) / (w @ n)[:, None]
    p_e = (p_j * p_j).sum(axis=1)
    return _ratio(p_bar - p_e, 1.0 - p_e)


def fleiss_kappa(table) -> float:
    """Fleiss κ (Fleiss 1971; see :func:`fleiss_kappa_counts`) of a subjects ×
    categories table of counts in which every subject was rated by the same number (≥ 2) of
    raters — the input of ``statsmodels.stats.inter_rater.fleiss_kappa``. Returns ``NaN``
    when every answer falls in one category (κ undefined).

    Parameters
    ----------
    table : array_like
        Subjects × categories counts, every row summing to the same number of raters.

    Returns
    -------
    float
        κ, or ``NaN``.
    """
    c = np.asarray(table, dtype=float)
    if c.ndim != 2 or c.shape[0] < 1:
        raise InvalidParameter(f"Fleiss κ table: must be subjects × categories, got shape {c.shape}")
    n = c.sum(axis=1)
    if np.any(n != n[0]) or n[0] < 2:
        raise InvalidParameter(
            "Fleiss κ table: every subject needs the same number (≥ 2) of ratings, got row sums "
            f"{sorted(set(n.tolist()))}")
    return float(fleiss_kappa_counts(c)[0])


# --------------------------------------------------------------------------- Krippendorff α
def krippendorff_alpha_counts(counts: np.ndarray, weights=None) -> np.ndarray:
    """Krippendorff α for nominal data from a units × categories count table, missing
    answers allowed (Krippendorff 2011, "Computing Krippendorff's alpha-reliability",
    Annenberg School for Communication, §"nominal data, any number of observers, missing
    data"): only units with ``m_u ≥ 2`` answers are pairable; the coincidences are
    ``o_ck = Σ_u (n_uc n_uk − δ_ck n_uc) / (m_u − 1)``, ``n_c = Σ_k o_ck``, ``n = Σ_c n_c`` and

    ``α = 1 − (n − 1) (n − Σ_c o_cc) / (n² − Σ_c n_c²)``

    (``1 − D_o/D_e`` with the nominal δ). One α per weight row; ``NaN`` where only one
    category occurs (``D_e = 0``).

    Parameters
    ----------
    counts : ndarray
        Units × categories counts (missing answers simply not counted).
    weights : ndarray, optional
        Replicates × units weights (bootstrap multiplicities).

    Returns
    -------
    ndarray
        α per replicate (one value without ``weights``).
    """
    c = np.asarray(counts, dtype=float)
    m = c.sum(axis=1)
    keep = m >= 2
    c, m = c[keep], m[keep]
    w = _weights(weights, keep.size)[:, keep]
    o_diag = ((c * c - c).sum(axis=1)) / (m - 1.0)       # Σ_c o_cc contributed by each unit
    n_c = w @ c                                          # replicates × categories
    n = n_c.sum(axis=1)
    return 1.0 - (n - 1.0) * _ratio(n - w @ o_diag, n * n - (n_c * n_c).sum(axis=1))


def krippendorff_alpha_nominal(data, categories: Sequence | None = None) -> float:
    """Krippendorff α, nominal level, of reliability data ``data`` (raters × units, ``NaN`` =
    missing; the layout of the ``krippendorff`` package). Krippendorff (2011); see
    :func:`krippendorff_alpha_counts`. ``NaN`` when fewer than two categories occur.

    Parameters
    ----------
    data : array_like
        Raters × units answers, ``NaN`` = missing.
    categories : sequence, optional
        The answer scale (default: the values present).

    Returns
    -------
    float
        α, or ``NaN``.
    """
    counts, _ = counts_table(data, categories)
    return float(krippendorff_alpha_counts(counts)[0])


# --------------------------------------------------------------------------- Gwet AC1
def gwet_ac1_counts(counts: np.ndarray, weights=None) -> np.ndarray:
    """Gwet's AC1 for any number of raters from a units × categories count table (Gwet 2008,
    "Computing inter-rater reliability and its variance in the presence of high agreement",
    British Journal of Mathematical and Statistical Psychology 61:29–48, the multiple-rater
    AC1; ``q`` = number of columns):

    ``p_a = mean_i Σ_k r_ik (r_ik − 1) / (r_i (r_i − 1))`` over units with ``r_i ≥ 2``,
    ``π_k = mean_i r_ik / r_i`` over units with ``r_i ≥ 1``,
    ``p_e = Σ_k π_k (1 − π_k) / (q − 1)``, ``AC1 = (p_a − p_e) / (1 − p_e)``.

    With every unit rated by everyone this is Gwet's formula as published; with missing
    answers the two means run over the units that allow them (the rule stated above and in
    docs/workshops.md). One AC1 per weight row.

    Parameters
    ----------
    counts : ndarray
        Units × categories counts; its columns are the answer scale.
    weights : ndarray, optional
        Replicates × units weights (bootstrap multiplicities).

    Returns
    -------
    ndarray
        AC1 per replicate (one value without ``weights``).
    """
    c = np.asarray(counts, dtype=float)
    q = c.shape[1]
    if q < 2:
        raise InvalidParameter(f"Gwet AC1: needs at least 2 categories, got {q}")
    r = c.sum(axis=1)
    w = _weights(weights, c.shape[0])
    pair = r >= 2
    with np.errstate(divide="ignore", invalid="ignore"):
        pa_i = np.where(pair, (c * (c - 1.0)).sum(axis=1) / (r * (r - 1.0)), 0.0)
        share = np.where((r >= 1)[:, None], c / r[:, None], 0.0)
    p_a = _ratio(w @ pa_i, w @ pair.astype(float))
    pi = (w @ share) / (w @ (r >= 1).astype(float))[:, None]
    p_e = (pi * (1.0 - pi)).sum(axis=1) / (q - 1.0)
    return _ratio(p_a - p_e, 1.0 - p_e)


def gwet_ac1(data, categories: Sequence | None = None) -> float:
    """Gwet's AC1 (Gwet 2008; see :func:`gwet_ac1_counts`) of reliability data ``data``
    (raters × units, ``NaN`` = missing). ``categories`` is the answer scale (for Yes/No
    ``(0, 1)``); it defaults to the values present, which must then be at least two.

    Parameters
    ----------
    data : array_like
        Raters × units answers, ``NaN`` = missing.
    categories : sequence, optional
        The answer scale, e.g. ``(0, 1)``.

    Returns
    -------
    float
        AC1.
    """
    counts, _ = counts_table(data, categories)
    return float(gwet_ac1_counts(counts)[0])


def gwet_ac1_two_raters(a, b, categories: Sequence | None = None) -> float:
    """Gwet's AC1 for two raters (Gwet 2008, the two-rater AC1): with ``p_kl`` the share of
    units rated ``k`` by rater A and ``l`` by rater B,

    ``p_a = Σ_k p_kk``, ``π_k = (p_k+ + p_+k) / 2``, ``p_e = Σ_k π_k (1 − π_k) / (q − 1)``,
    ``AC1 = (p_a − p_e) / (1 − p_e)``.

    ``a`` and ``b`` are the two raters' answers on the same units (no missing answers).

    Parameters
    ----------
    a, b : array_like
        The two raters' answers on the same units.
    categories : sequence, optional
        The answer scale (default: the values present).

    Returns
    -------
    float
        AC1.
    """
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if x.shape != y.shape or x.ndim != 1 or x.size == 0:
        raise InvalidParameter(f"Gwet AC1 (two raters): need two equal-length answer lists, got {x.shape}, {y.shape}")
    if np.isnan(x).any() or np.isnan(y).any():
        raise InvalidParameter("Gwet AC1 (two raters): missing answers are not allowed")
    cats = sorted(set(x.tolist()) | set(y.tolist())) if categories is None else [float(c) for c in categories]
    if len(cats) < 2:
        raise InvalidParameter(f"Gwet AC1 (two raters): needs at least 2 categories, got {cats}")
    p_a = float(np.mean(x == y))
    pi = np.array([(np.mean(x == c) + np.mean(y == c)) / 2.0 for c in cats])
    p_e = float((pi * (1.0 - pi)).sum() / (len(cats) - 1.0))
    return (p_a - p_e) / (1.0 - p_e)


# --------------------------------------------------------------------------- McNemar
def mcnemar_exact(table) -> tuple[float, float]:
    """Exact McNemar test of a paired 2×2 table ``[[a, b], [c, d]]`` (McNemar 1947,
    "Note on the sampling error of the difference between correlated proportions or
    percentages", Psychometrika 12:153–157; exact form: the two-sided binomial test of
    ``b`` out of the ``b + c`` discordant pairs with p = ½, Agresti 2013, Categorical Data
    Analysis, 3rd ed., §11.1). Computed by ``statsmodels.stats.contingency_tables.mcnemar``
    with ``exact=True``; returns ``(statistic, p_value)`` with statistic ``min(b, c)``.

    Parameters
    ----------
    table : array_like
        Paired 2×2 table of counts ``[[a, b], [c, d]]``.

    Returns
    -------
    tuple of (float, float)
        ``(statistic, p_value)``, statistic ``min(b, c)``.

    Examples
    --------
    >>> mcnemar_exact([[10, 2], [8, 5]])
    (2.0, 0.109375)
    """
    t = np.asarray(table, dtype=float)
    if t.shape != (2, 2) or np.any(t < 0) or np.any(t != np.round(t)):
        raise InvalidParameter(f"McNemar table: must be a 2×2 table of counts, got {table!r}")
    from statsmodels.stats.contingency_tables import mcnemar

    res = mcnemar(t, exact=True)
    return float(res.statistic), float(res.pvalue)

"""The analysis of one expert review workshop (issue 15 item 5; docs/workshops.md "Statistics").

:func:`analyse` takes the answers and the plots of a workshop as two pandas DataFrames and
returns a :class:`WorkshopAnalysis`; ``to_dict()`` is the JSON of ``railval workshop analyse``:

* ``table1`` — per plot kind, the number of plots and the smallest and largest share of Yes
  over the reviewers (Polach & Böttcher 2014 §4.2, Table 1; shares in [0, 1], not percent);
* ``reviewers`` — per reviewer the number of first answers, the share of Yes with its Wilson
  interval, the strictness (Rasch-type model) with its interval, and the consistency on
  hidden repeats;
* ``agreement`` — Fleiss κ, Krippendorff α and Gwet AC1, each with a percentile bootstrap
  interval over plots;
* ``threshold`` — the normalised deviation (and the Sprague–Geers C) at which a typical
  reviewer says Yes half of the time, model-free in the link (isotonic regression of the
  reviewer-adjusted acceptability, bootstrap interval over plots), with ``method`` and the
  ``link_sensitivity`` of the parametric links (:mod:`.threshold`);
* ``scaling_effect`` — the paired comparison of the same reviewer's answers on the same plot
  at the workshop's fixed scaling and at automatic scaling (exact McNemar test), or ``None``.

Which answers count where
-------------------------
A *first answer* is an answer that is neither a hidden repeat nor an automatic-scaling
showing (``repeat`` False and ``scaling == "fixed"``); each (reviewer, plot) has at most one.
Only first answers enter Table 1, the shares of Yes, the agreement statistics, the Rasch
model and the threshold. Hidden repeats (``repeat`` True, fixed scaling) are compared with
the same reviewer's first answer on that plot (consistency = share of equal answers);
automatic-scaling showings (``scaling == "auto"``) are paired with the first answer on that
plot (scaling effect). Repeats or automatic showings without a first answer are left out.

Missing answers (a reviewer who has not finished) are allowed: Krippendorff α and Gwet AC1
use every plot with enough answers (their own missing-data rules, :mod:`.agreement`); Fleiss
κ needs the same raters on every plot and is computed on the largest complete block — the
reviewers ordered by their number of first answers (most first, then by name), the top ``m``
of them for the ``m ≥ 2`` that maximises ``m × (plots answered by all top m)`` (ties: the
larger ``m``) — and reports how many reviewers and plots that block has.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from railval.core.errors import InvalidParameter
from railval.core.review.agreement import (
    fleiss_kappa_counts,
    gwet_ac1_counts,
    krippendorff_alpha_counts,
    mcnemar_exact,
    wilson_interval,
)
from railval.core.review.rasch import fit_rasch
from railval.core.review.threshold import DEFAULT_BOOT, TOO_FEW, link_sensitivity, monotone_threshold

__all__ = ["ANSWER_COLUMNS", "PLOT_COLUMNS", "SCALINGS", "WorkshopAnalysis", "analyse"]

ANSWER_COLUMNS = ("reviewer", "plot", "answer", "repeat", "scaling", "seconds")
PLOT_COLUMNS = ("plot", "kind", "deviation", "sg_c")
SCALINGS = ("fixed", "auto")
CONFIDENCE = 0.95
#: ``threshold.method`` of the JSON: how the 50 % values are estimated (:mod:`.threshold`).
THRESHOLD_METHOD = ("isotonic: falling isotonic regression (pooled adjacent violators) of the reviewer-adjusted "
                    "acceptability on the objective value; the 50 % value is where the drawn curve of a typical "
                    "reviewer crosses 50 % (linear between adjacent values, Stylianou & Flournoy 2002); "
                    "percentile bootstrap over plots (Davison & Hinkley 1997 §3.8)")
#: The fewest first answers (on plots with the objective value) and plots a 50 % value is
#: reported from; below either the status is "too few answers to estimate" (docs/workshops.md
#: "Too few answers", where the measured behaviour of smaller workshops is given).
MIN_ANSWERS = 20
MIN_PLOTS = 12
#: ``strictness_note`` of a reviewer when fewer than two reviewers answered.
STRICTNESS_ALONE = "cannot be estimated with one reviewer (strictness is relative to the panel's mean reviewer)"


@dataclass(frozen=True)
class WorkshopAnalysis:
    """The analysis of one workshop (module docstring). The five fields are the JSON of
    :meth:`to_dict`; ``plots`` (not part of it) holds per plot ``plot, kind, answers,
    yes_share, acceptability, acceptability_ci, deviation, sg_c`` for the analysis page's
    scatter of answers against the objective values."""

    table1: list[dict]
    reviewers: list[dict]
    agreement: dict
    threshold: dict
    scaling_effect: dict | None
    plots: list[dict] = field(default_factory=list)

    def to_dict(self) -> dict:
        """``{"table1", "reviewers", "agreement", "threshold", "scaling_effect"}`` — plain
        Python values (floats, ints, str, lists, None), ready for ``json.dumps``."""
        return copy.deepcopy({
            "table1": self.table1,
            "reviewers": self.reviewers,
            "agreement": self.agreement,
            "threshold": self.threshold,
            "scaling_effect": self.scaling_effect,
        })


# --------------------------------------------------------------------------- helpers
def _f(x) -> float | None:
    """A finite float or None (JSON has no NaN)."""
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def _interval(lo, hi) -> list[float] | None:
    lo, hi = _f(lo), _f(hi)
    return None if lo is None or hi is None else [lo, hi]


def _where(frame: str, idx, row: pd.Series | None = None) -> str:
    if row is None:
        return f"{frame} row {idx}"
    return f"{frame} row {idx} (reviewer {row['reviewer']!r}, plot {row['plot']!r})"


def _show(v) -> str:
    """``repr`` of a cell value as the user wrote it (numpy scalars as plain Python)."""
    return repr(v.item() if isinstance(v, np.generic) else v)


def _bool_column(df: pd.DataFrame, col: str, frame: str) -> np.ndarray:
    s = df[col]
    if s.dtype == bool:
        return s.to_numpy()
    out = np.empty(len(s), dtype=bool)
    for i, (idx, v) in enumerate(s.items()):
        if isinstance(v, (bool, np.bool_)) or (isinstance(v, (int, np.integer)) and v in (0, 1)):
            out[i] = bool(v)
        else:
            row = df.loc[idx] if frame == "answers" else None
            raise InvalidParameter(f"{_where(frame, idx, row)}: column {col!r} must be True/False, got {_show(v)}")
    return out


def _prepare(answers: pd.DataFrame, plots: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Check both frames and return normalised copies (str ids, bool flags, float values)."""
    for name, df, cols in (("answers", answers, ANSWER_COLUMNS), ("plots", plots, PLOT_COLUMNS)):
        if not isinstance(df, pd.DataFrame):
            raise InvalidParameter(f"{name}: must be a pandas DataFrame, got {type(df).__name__}")
        missing = [c for c in cols if c not in df.columns]
        if missing:
            raise InvalidParameter(f"{name}: missing column(s) {missing}; required {list(cols)}")
    p = pd.DataFrame({
        "plot": plots["plot"].astype(str).to_numpy(),
        "kind": plots["kind"].astype(str).to_numpy(),
    })
    for col in ("deviation", "sg_c"):
        vals = pd.to_numeric(plots[col].astype(object).where(plots[col].notna(), np.nan), errors="coerce")
        bad = plots[col].notna().to_numpy() & vals.isna().to_numpy()
        neg = (vals < 0).to_numpy()
        for mask, what in ((bad, "a number or missing"), (neg, "≥ 0")):
            if mask.any():
                i = int(np.flatnonzero(mask)[0])
                raise InvalidParameter(f"plots row {plots.index[i]} (plot {p['plot'].iloc[i]!r}): column "
                                       f"{col!r} must be {what}, got {_show(plots[col].iloc[i])}")
        p[col] = vals.to_numpy(dtype=float)
    dup = p["plot"].duplicated()
    if dup.any():
        i = int(np.flatnonzero(dup.to_numpy())[0])
        raise InvalidParameter(f"plots row {plots.index[i]}: duplicate plot id {p['plot'].iloc[i]!r}")

    a = pd.DataFrame({
        "reviewer": answers["reviewer"].astype(str).to_numpy(),
        "plot": answers["plot"].astype(str).to_numpy(),
    }, index=answers.index)
    a["answer"] = _bool_column(answers.assign(reviewer=a["reviewer"], plot=a["plot"]), "answer", "answers")
    a["repeat"] = _bool_column(answers.assign(reviewer=a["reviewer"], plot=a["plot"]), "repeat", "answers")
    scaling = answers["scaling"].astype(str).str.lower()
    bad = ~scaling.isin(SCALINGS)
    if bad.any():
        idx = bad[bad].index[0]
        raise InvalidParameter(f"{_where('answers', idx, a.loc[idx])}: column 'scaling' must be one of "
                               f"{list(SCALINGS)}, got {_show(answers.loc[idx, 'scaling'])}")
    a["scaling"] = scaling.to_numpy()
    secs = pd.to_numeric(answers["seconds"], errors="coerce")
    bad = (answers["seconds"].notna() & secs.isna()) | (secs < 0)
    if bad.any():
        idx = bad[bad].index[0]
        raise InvalidParameter(f"{_where('answers', idx, a.loc[idx])}: column 'seconds' must be a number "
                               f"≥ 0, got {_show(answers.loc[idx, 'seconds'])}")
    a["seconds"] = secs.to_numpy(dtype=float)
    unknown = ~a["plot"].isin(set(p["plot"]))
    if unknown.any():
        idx = unknown[unknown].index[0]
        raise InvalidParameter(f"{_where('answers', idx, a.loc[idx])}: plot {a.loc[idx, 'plot']!r} is not "
                               "among the workshop's plots")
    for label, mask in (("first answer", ~a["repeat"] & (a["scaling"] == "fixed")),
                        ("automatic-scaling answer", a["scaling"] == "auto")):
        sub = a[mask]
        dup = sub.duplicated(["reviewer", "plot"])
        if dup.any():
            idx = dup[dup].index[0]
            raise InvalidParameter(f"{_where('answers', idx, a.loc[idx])}: a second {label} of this "
                                   "reviewer on this plot")
    return a, p


def _bootstrap_ci(stat, counts: np.ndarray, n_boot: int, rng: np.random.Generator):
    """Percentile bootstrap interval over units (rows of ``counts``) of ``stat(counts, W)``
    (Efron & Tibshirani 1993, An Introduction to the Bootstrap, ch. 13), all replicates in
    one call; undefined replicates (NaN) are left out."""
    n = counts.shape[0]
    if n_boot <= 0 or n < 2:
        return None
    draws = rng.integers(0, n, size=(n_boot, n))
    w = np.zeros((n_boot, n))
    np.add.at(w, (np.repeat(np.arange(n_boot), n), draws.ravel()), 1.0)
    reps = np.asarray(stat(counts, w), dtype=float)
    reps = reps[np.isfinite(reps)]
    if reps.size == 0:
        return None
    alpha = (1.0 - CONFIDENCE) / 2.0
    lo, hi = np.quantile(reps, [alpha, 1.0 - alpha])
    return _interval(lo, hi)


def _fleiss_block(y: np.ndarray, names: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Largest complete block (module docstring): boolean masks (reviewers, plots)."""
    answered = ~np.isnan(y)
    n_ans = answered.sum(axis=1)
    order = sorted(range(len(names)), key=lambda i: (-n_ans[i], names[i]))
    best = (0, 0, np.zeros(y.shape[1], dtype=bool))
    common = np.ones(y.shape[1], dtype=bool)
    for m, i in enumerate(order, start=1):
        common = common & answered[i]
        size = m * int(common.sum())
        if m >= 2 and size >= best[0] and common.sum() >= 1:
            best = (size, m, common.copy())
    rev = np.zeros(len(names), dtype=bool)
    rev[order[: best[1]]] = True
    return rev, best[2]


def _agreement(y: np.ndarray, names: list[str], n_boot: int, rng: np.random.Generator) -> dict:
    """Fleiss κ, Krippendorff α, Gwet AC1 of the reviewers × plots matrix ``y`` (1 = Yes,
    0 = No, NaN = no first answer)."""
    yes = np.nansum(y == 1, axis=0).astype(float)
    no = np.nansum(y == 0, axis=0).astype(float)
    counts = np.stack([no, yes], axis=1)
    m = counts.sum(axis=1)
    out: dict = {}

    rev, blk = _fleiss_block(y, names)
    sub = np.zeros((0, 2))
    if rev.sum() >= 2 and blk.sum() >= 1:
        block = y[rev][:, blk]
        sub = np.stack([(block == 0).sum(axis=0), (block == 1).sum(axis=0)], axis=1).astype(float)
        value = fleiss_kappa_counts(sub)[0]
        ci = _bootstrap_ci(fleiss_kappa_counts, sub, n_boot, rng) if _f(value) is not None else None
    else:
        value, ci = np.nan, None
    out["fleiss_kappa"] = {"value": _f(value), "ci": ci, "plots": int(sub.shape[0]), "reviewers": int(rev.sum())}

    pairable = counts[m >= 2]
    raters = int((~np.isnan(y[:, m >= 2])).any(axis=1).sum())
    if pairable.shape[0] >= 1:
        value = krippendorff_alpha_counts(pairable)[0]
        ci = _bootstrap_ci(krippendorff_alpha_counts, pairable, n_boot, rng) if _f(value) is not None else None
    else:
        value, ci = np.nan, None
    out["krippendorff_alpha"] = {"value": _f(value), "ci": ci, "plots": int(pairable.shape[0]),
                                 "reviewers": raters}

    rated = counts[m >= 1]
    if pairable.shape[0] >= 1:
        value = gwet_ac1_counts(rated)[0]
        ci = _bootstrap_ci(gwet_ac1_counts, rated, n_boot, rng) if _f(value) is not None else None
    else:
        value, ci = np.nan, None
    out["gwet_ac1"] = {"value": _f(value), "ci": ci, "plots": int(pairable.shape[0]), "reviewers": raters}
    return out


# --------------------------------------------------------------------------- analyse
def analyse(answers: pd.DataFrame, plots: pd.DataFrame, *, n_boot: int = 1000, seed: int = 0,
            threshold_boot: int = DEFAULT_BOOT) -> WorkshopAnalysis:
    """Analyse one workshop (module docstring).

    Parameters
    ----------
    answers : pandas.DataFrame
        One row per answer given, columns ``reviewer`` (str), ``plot`` (plot id), ``answer``
        (bool, True = Yes), ``repeat`` (bool, a hidden repeat showing), ``scaling``
        (``"fixed"`` or ``"auto"``), ``seconds`` (time on the plot, float, may be NaN).
    plots : pandas.DataFrame
        One row per plot, columns ``plot`` (id), ``kind``, ``deviation`` (normalised
        |D_v| / std limit, NaN if none) and ``sg_c`` (Sprague–Geers C, NaN if none).
    n_boot : int
        Bootstrap replicates for the agreement intervals (0 = none).
    seed : int
        Their random seed (the result is reproducible).
    threshold_boot : int
        Bootstrap replicates of the 50 % values' intervals (over plots; 0 = no interval).

    Returns
    -------
    WorkshopAnalysis
        Table 1, reviewers, agreement, threshold, scaling effect and per-plot rows.

    Raises :class:`~railval.core.errors.InvalidParameter` naming the row and column of a bad
    value, an answer on an unknown plot or a second first answer of one reviewer on one plot.
    """
    if int(n_boot) < 0:
        raise InvalidParameter(f"n_boot: must be ≥ 0, got {n_boot!r}")
    if int(threshold_boot) < 0:
        raise InvalidParameter(f"threshold_boot: must be ≥ 0, got {threshold_boot!r}")
    a, p = _prepare(answers, plots)
    rng = np.random.default_rng(seed)
    first = a[~a["repeat"] & (a["scaling"] == "fixed")]
    names = sorted(a["reviewer"].unique().tolist())
    plot_ids = p["plot"].tolist()
    r_index = {n: i for i, n in enumerate(names)}
    p_index = {q: i for i, q in enumerate(plot_ids)}
    fr = first["reviewer"].map(r_index).to_numpy(dtype=np.int64)
    fp = first["plot"].map(p_index).to_numpy(dtype=np.int64)
    fy = first["answer"].to_numpy(dtype=float)
    y = np.full((len(names), len(plot_ids)), np.nan)
    y[fr, fp] = fy
    kinds = p["kind"].to_numpy()
    strict, accept = _rasch(y, fr, fp, fy)
    reviewers = _reviewer_rows(a, first, names, y, strict)
    agreement = _agreement(y, names, int(n_boot), rng)  # before the threshold: both draw from ``rng``
    threshold = _threshold(p, accept[0], first["reviewer"].to_numpy(), fp, fy, int(threshold_boot), rng)
    plot_rows = []
    for j, q in enumerate(plot_ids):
        col = y[:, j]
        n = int((~np.isnan(col)).sum())
        plot_rows.append({
            "plot": q, "kind": kinds[j], "answers": n,
            "yes_share": _f(np.nansum(col) / n) if n else None,
            "acceptability": _f(accept[0][j]), "acceptability_ci": _interval(accept[1][j], accept[2][j]),
            "deviation": _f(p["deviation"].iloc[j]), "sg_c": _f(p["sg_c"].iloc[j]),
        })
    return WorkshopAnalysis(_table1(y, kinds), reviewers, agreement, threshold, _scaling_effect(a, first),
                            plot_rows)


def _table1(y: np.ndarray, kinds: np.ndarray) -> list[dict]:
    """Per plot kind: plots, reviewers, first answers and the smallest and largest share of
    Yes over the reviewers, each with the Yes count and answers it rests on (``min_yes_count``
    of ``min_yes_answers``; the first such reviewer), on the first answers ``y`` (reviewer ×
    plot, NaN = none) — Polach & Böttcher 2014 §4.2, Table 1."""
    table1 = []
    for kind in dict.fromkeys(kinds.tolist()):
        cols = kinds == kind
        n_ans = (~np.isnan(y[:, cols])).sum(axis=1)
        k_yes = np.nansum(y[:, cols], axis=1)
        has = n_ans > 0
        share = k_yes[has] / n_ans[has]
        row = {"kind": kind, "plots": int(cols.sum()), "reviewers": int(has.sum()), "answers": int(n_ans.sum())}
        for end, pick in (("min", np.argmin), ("max", np.argmax)):
            i = int(pick(share)) if share.size else None
            row[f"{end}_yes"] = _f(share[i]) if i is not None else None
            row[f"{end}_yes_count"] = int(k_yes[has][i]) if i is not None else None
            row[f"{end}_yes_answers"] = int(n_ans[has][i]) if i is not None else None
        table1.append(row)
    return table1


def _rasch(y: np.ndarray, fr: np.ndarray, fp: np.ndarray,
           fy: np.ndarray) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
    """((strictness, lower, upper) per reviewer, (acceptability, lower, upper) per plot) of the
    Rasch-type model (:func:`railval.core.review.rasch.fit_rasch`) on the first answers
    (``fr``, ``fp``, ``fy``: reviewer index, plot index, answer); NaN where a reviewer or a
    plot has no first answer."""
    n_r, n_p = y.shape
    strict = tuple(np.full(n_r, np.nan) for _ in range(3))
    accept = tuple(np.full(n_p, np.nan) for _ in range(3))
    if fy.size:
        act_r = np.flatnonzero((~np.isnan(y)).any(axis=1))
        act_p = np.flatnonzero((~np.isnan(y)).any(axis=0))
        fit = fit_rasch(np.searchsorted(act_r, fr), np.searchsorted(act_p, fp), fy,
                        n_reviewers=act_r.size, n_plots=act_p.size)
        strict[0][act_r] = fit.strictness
        strict[1][act_r], strict[2][act_r] = fit.strictness_ci(CONFIDENCE)
        accept[0][act_p] = fit.acceptability
        accept[1][act_p], accept[2][act_p] = fit.acceptability_ci(CONFIDENCE)
    return strict, accept


def _reviewer_rows(a: pd.DataFrame, first: pd.DataFrame, names: list[str], y: np.ndarray,
                   strict: tuple[np.ndarray, ...]) -> list[dict]:
    """Per reviewer: first answers, share of Yes with its Wilson interval, strictness with its
    interval (``None`` with a ``strictness_note`` when fewer than two reviewers answered),
    consistency on hidden repeats and median time per plot."""
    reps = a[a["repeat"] & (a["scaling"] == "fixed")]
    paired = reps.merge(first[["reviewer", "plot", "answer"]], on=["reviewer", "plot"], suffixes=("", "_first"))
    same = (paired["answer"] == paired["answer_first"]).groupby(paired["reviewer"]).agg(["sum", "count"])
    # strictness is relative to the panel's mean reviewer: with one reviewer it is 0 by
    # construction, not an estimate
    alone = STRICTNESS_ALONE if int((~np.isnan(y)).any(axis=1).sum()) < 2 else None
    reviewers = []
    for i, name in enumerate(names):
        row = y[i]
        n = int((~np.isnan(row)).sum())
        k = int(np.nansum(row))
        ci = wilson_interval(k, n, confidence=CONFIDENCE) if n else None
        n_rep = int(same.loc[name, "count"]) if name in same.index else 0
        secs = a.loc[a["reviewer"] == name, "seconds"].to_numpy()
        secs = secs[np.isfinite(secs)]
        reviewers.append({
            "reviewer": name, "answers": n,
            "yes_share": _f(k / n) if n else None,
            "yes_share_ci": _interval(*ci) if ci else None,
            "strictness": _f(strict[0][i]) if alone is None else None,
            "strictness_ci": _interval(strict[1][i], strict[2][i]) if alone is None else None,
            "strictness_note": alone,
            "consistency": _f(same.loc[name, "sum"] / n_rep) if n_rep else None,
            "repeats": n_rep,
            "median_seconds": _f(np.median(secs)) if secs.size else None,
        })
    return reviewers


def _threshold(p: pd.DataFrame, accept: np.ndarray, fnames: np.ndarray, fp: np.ndarray, fy: np.ndarray,
               threshold_boot: int, rng: np.random.Generator) -> dict:
    """The objective value at which a typical reviewer says Yes half of the time, model-free in
    the link (isotonic on the reviewer-adjusted acceptability ``accept``,
    :func:`railval.core.review.threshold.monotone_threshold`: the reported value is the
    crossing of the drawn curve), with the parametric links beside it
    (:func:`railval.core.review.threshold.link_sensitivity`; the drawn dashed curve is the
    likeliest link), for the normalised deviation and the Sprague–Geers C. Each carries its
    n (``deviation_n``/``sg_c_n``: first answers, reviewers and plots it rests on) and its
    ``…_status``; below :data:`MIN_ANSWERS` answers or :data:`MIN_PLOTS` plots the value and
    interval are ``None`` and the status says "too few answers to estimate"."""
    threshold: dict = {"method": THRESHOLD_METHOD, "min_answers": MIN_ANSWERS, "min_plots": MIN_PLOTS}
    for col, key, ci_key in (("deviation", "deviation_at_50", "ci"), ("sg_c", "sg_c_at_50", "sg_c_ci")):
        vals = p[col].to_numpy()
        mono = monotone_threshold(vals, accept, n_boot=threshold_boot, seed=rng, confidence=CONFIDENCE)
        used = np.isfinite(vals[fp]) & np.isfinite(accept[fp])
        n = {"answers": int(used.sum()), "reviewers": int(np.unique(fnames[used]).size), "plots": int(mono.plots)}
        enough = n["answers"] >= MIN_ANSWERS and n["plots"] >= MIN_PLOTS
        best, sens = link_sensitivity(vals[fp], fy, fnames, fp, reference=mono.at_50, confidence=CONFIDENCE)
        threshold[key] = _f(mono.at_50) if enough else None
        threshold[ci_key] = (_interval(*mono.ci) if mono.ci else None) if enough else None
        threshold[f"{key}_status"] = mono.status if enough else TOO_FEW
        threshold[f"{ci_key}_status"] = mono.ci_status if enough else None
        threshold[f"{col}_n"] = n
        threshold[f"{col}_curve"] = {"value": [_f(x) for x in mono.curve_value],
                                     "yes": [_f(x) for x in mono.curve_yes]}
        threshold[f"{col}_fit"] = {k: (_f(v) if isinstance(v, float) else v) for k, v in best.to_dict().items()
                                   if k not in ("at_50", "ci")}
        threshold["link_sensitivity" if col == "deviation" else "sg_c_link_sensitivity"] = {
            **sens, "relative_spread": _f(sens["relative_spread"]),
            "links": [{k: (_f(v) if isinstance(v, float) and k != "power" else v) for k, v in row.items()}
                      for row in sens["links"]],
            "boot_valid": mono.boot_valid, "n_boot": mono.n_boot,
        }
    return threshold


def _scaling_effect(a: pd.DataFrame, first: pd.DataFrame) -> dict | None:
    """The presentation experiment: each automatic-scaling showing paired with the same
    reviewer's first answer on that plot, compared with the exact McNemar test
    (:func:`railval.core.review.agreement.mcnemar_exact`); ``None`` without pairs."""
    auto = a[a["scaling"] == "auto"]
    if not len(auto):
        return None
    pair = auto.merge(first[["reviewer", "plot", "answer"]], on=["reviewer", "plot"], suffixes=("_auto", ""))
    if not len(pair):
        return None
    fx, au = pair["answer"].to_numpy(), pair["answer_auto"].to_numpy()
    table = np.array([[np.sum(fx & au), np.sum(fx & ~au)], [np.sum(~fx & au), np.sum(~fx & ~au)]])
    stat, pval = mcnemar_exact(table)
    changed = int(table[0, 1] + table[1, 0])
    return {
        "pairs": len(pair), "changed": changed,
        "changed_share": _f(changed / len(pair)),
        "changed_share_ci": _interval(*wilson_interval(changed, len(pair), confidence=CONFIDENCE)),
        "fixed_yes_share": _f(fx.mean()), "auto_yes_share": _f(au.mean()),
        "fixed_yes_auto_no": int(table[0, 1]), "fixed_no_auto_yes": int(table[1, 0]),
        "statistic": _f(stat), "p_value": _f(pval), "test": "McNemar exact (binomial)",
    }

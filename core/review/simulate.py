"""Simulated review workshops with known truth, for tests and benchmarks (docs/workshops.md).

Reviewers of known strictness ``s_r`` answer plots of known acceptability ``a_p`` by the
model of :mod:`railval.core.review.rasch`: Yes with probability ``expit(a_p − s_r)``. In
:func:`simulate_workshop` a plot's acceptability follows its normalised deviation ``d_p``:

    a_p = slope · (log d_p − log d₅₀) + u_p,   u_p ~ N(0, plot_sd²),   slope < 0

(``response="log"``, the default), or — reviewers who answer on the deviation itself or on
a hard limit with noise — ``response="linear"``: ``a_p = slope/d₅₀ · (d_p − d₅₀) + u_p`` (the
same local slope at ``d₅₀``), ``response="step"``: ``a_p = −slope · sign(d₅₀ − d_p)·½ + u_p``
(a step of height ``|slope|`` logits at ``d₅₀``). In every case a typical reviewer
(strictness 0) says Yes half of the time at ``d₅₀`` — by the symmetry
of ``u_p`` also on average over plots. True strictness values are centred to mean 0 exactly,
which is the scale the analysis reports. Deviations are log-normal around 1
(``exp(N(0, deviation_spread²))``). Hidden repeats are answered again by the same model
(independently), automatic-scaling showings with the logit shifted by ``auto_shift``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
import scipy.special

from railval.core.errors import InvalidParameter

__all__ = ["DEFAULT_KINDS", "RESPONSES", "SimulatedWorkshop", "simulate_answers", "simulate_workshop",
           "yes_probability"]

#: Plot kinds of the DynoTRAIN workshop (Polach & Böttcher 2014 Table 1), cycled over the plots.
DEFAULT_KINDS = ("Y", "Q", "Y/Q", "bogie acceleration", "car body acceleration", "PSD")

#: Response curves of :func:`simulate_workshop` (module docstring).
RESPONSES = ("log", "linear", "step")


def yes_probability(acceptability, strictness):
    """``P(Yes) = expit(acceptability − strictness)`` (the Rasch-type model).

    Parameters
    ----------
    acceptability : float or array_like
        Plot acceptability (logits).
    strictness : float or array_like
        Reviewer strictness (logits).

    Returns
    -------
    float or ndarray
        The probability of a Yes.

    Examples
    --------
    >>> float(yes_probability(1.0, 1.0))
    0.5
    """
    return scipy.special.expit(np.asarray(acceptability, dtype=float) - np.asarray(strictness, dtype=float))


@dataclass(frozen=True)
class SimulatedWorkshop:
    """A simulated workshop: ``answers`` and ``plots`` in the layout :func:`railval.core.
    review.analysis.analyse` takes, and the truth: ``strictness`` (reviewer → s_r, mean 0),
    ``acceptability`` (plot → a_p), ``deviation_at_50`` (d₅₀) and ``slope``."""

    answers: pd.DataFrame
    plots: pd.DataFrame
    strictness: dict[str, float]
    acceptability: dict[str, float]
    deviation_at_50: float
    slope: float


def simulate_answers(acceptability: Mapping[str, float], strictness: Mapping[str, float], *,
                     seed: int | np.random.Generator = 0, repeat_share: float = 0.1,
                     auto_share: float = 0.0, auto_shift: float = 0.0,
                     answer_share: float = 1.0) -> pd.DataFrame:
    """Answers of every reviewer in ``strictness`` on the plots in ``acceptability``.

    Each reviewer answers each plot once (first showing, fixed scaling) — or, with
    ``answer_share < 1``, a random share of the plots (an unfinished reviewer) — plus hidden
    repeats of a random ``repeat_share`` of the answered plots and automatic-scaling
    showings of a random ``auto_share`` (logit shifted by ``auto_shift``). Columns:
    ``reviewer, plot, answer, repeat, scaling, seconds`` (seconds log-normal around 8 s).
    Rows are in answering order per reviewer (first showings, then repeats and automatic
    showings). Plot ids and reviewer names are the mapping keys (as str).

    Parameters
    ----------
    acceptability : mapping of str to float
        Plot id → acceptability (logits).
    strictness : mapping of str to float
        Reviewer name → strictness (logits).
    seed : int or numpy.random.Generator
        Random seed or generator.
    repeat_share, auto_share, answer_share : float
        Shares of hidden repeats, automatic-scaling showings and answered plots.
    auto_shift : float
        Logit shift of the automatic-scaling showings.

    Returns
    -------
    pandas.DataFrame
        One row per answer, the columns of :func:`railval.core.review.analysis.analyse`.
    """
    for name, share in (("repeat_share", repeat_share), ("auto_share", auto_share),
                        ("answer_share", answer_share)):
        if not 0.0 <= share <= 1.0:
            raise InvalidParameter(f"{name}: must lie in [0, 1], got {share!r}")
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    plot_ids = [str(p) for p in acceptability]
    acc = np.array([float(acceptability[p]) for p in acceptability])
    rows: dict[str, list] = {k: [] for k in ("reviewer", "plot", "answer", "repeat", "scaling", "seconds")}

    def emit(reviewer: str, idx: np.ndarray, s: float, repeat: bool, scaling: str, shift: float):
        yes = rng.random(idx.size) < yes_probability(acc[idx] + shift, s)
        rows["reviewer"] += [reviewer] * idx.size
        rows["plot"] += [plot_ids[i] for i in idx]
        rows["answer"] += yes.tolist()
        rows["repeat"] += [repeat] * idx.size
        rows["scaling"] += [scaling] * idx.size
        rows["seconds"] += np.round(rng.lognormal(np.log(8.0), 0.5, idx.size), 2).tolist()

    n = acc.size
    for reviewer, s in strictness.items():
        order = rng.permutation(n)
        answered = order[: round(answer_share * n)]
        emit(str(reviewer), answered, float(s), False, "fixed", 0.0)
        k_rep = round(repeat_share * answered.size)
        emit(str(reviewer), rng.choice(answered, k_rep, replace=False), float(s), True, "fixed", 0.0)
        k_auto = round(auto_share * answered.size)
        emit(str(reviewer), rng.choice(answered, k_auto, replace=False), float(s), False, "auto",
             float(auto_shift))
    return pd.DataFrame({
        "reviewer": pd.Series(rows["reviewer"], dtype=object),
        "plot": pd.Series(rows["plot"], dtype=object),
        "answer": pd.Series(rows["answer"], dtype=bool),
        "repeat": pd.Series(rows["repeat"], dtype=bool),
        "scaling": pd.Series(rows["scaling"], dtype=object),
        "seconds": pd.Series(rows["seconds"], dtype=float),
    })


def simulate_workshop(n_reviewers: int = 20, n_plots: int = 120, *, seed: int = 0,
                      deviation_at_50: float = 1.2, slope: float = -3.0,
                      deviation_spread: float = 0.5, plot_sd: float = 0.5,
                      strictness_sd: float = 1.0, repeat_share: float = 0.1,
                      auto_share: float = 0.0, auto_shift: float = 0.0,
                      kinds: Sequence[str] = DEFAULT_KINDS, no_deviation_share: float = 0.0,
                      answer_share: float = 1.0, response: str = "log") -> SimulatedWorkshop:
    """A whole simulated workshop (module docstring).

    Reviewers are named ``"r01"`` …, plots ``"p001"`` …; plot kinds cycle through ``kinds``.
    A random ``no_deviation_share`` of the plots gets no deviation (NaN — a signal without
    an EN quantity); their acceptability is drawn around that of d = 1. ``sg_c`` (Sprague–
    Geers C) is simulated as ``0.25 · d · exp(N(0, 0.2²))``.

    Parameters
    ----------
    n_reviewers, n_plots : int
        Numbers of reviewers and plots (≥ 1).
    seed : int
        Random seed.
    deviation_at_50 : float
        Normalised deviation at which a typical reviewer says Yes half of the time (> 0).
    slope : float
        Slope of the response in the deviation (< 0).
    deviation_spread, plot_sd, strictness_sd : float
        Spread of log deviation, of plot acceptability around the response, of strictness.
    repeat_share, auto_share, auto_shift, answer_share : float
        As in :func:`simulate_answers`.
    kinds : sequence of str
        Plot kinds, cycled.
    no_deviation_share : float
        Share of plots without a deviation.
    response : str
        ``"log"``, ``"linear"`` or ``"step"``: the response's shape in the deviation.

    Returns
    -------
    SimulatedWorkshop
        Answers, plots and the true strictness, acceptability, ``deviation_at_50`` and slope.
    """
    if n_reviewers < 1 or n_plots < 1:
        raise InvalidParameter(f"simulate_workshop: need ≥ 1 reviewer and plot, got {n_reviewers}, {n_plots}")
    if not slope < 0 or not deviation_at_50 > 0:
        raise InvalidParameter(f"simulate_workshop: need slope < 0 and deviation_at_50 > 0, "
                               f"got {slope!r}, {deviation_at_50!r}")
    if response not in RESPONSES:
        raise InvalidParameter(f"simulate_workshop: response must be one of {', '.join(RESPONSES)}, "
                               f"got {response!r}")
    rng = np.random.default_rng(seed)
    s = rng.normal(0.0, strictness_sd, n_reviewers)
    s -= s.mean()
    d = np.exp(rng.normal(0.0, deviation_spread, n_plots))
    if response == "log":
        centre = slope * (np.log(d) - np.log(deviation_at_50))
    elif response == "linear":
        centre = slope / deviation_at_50 * (d - deviation_at_50)
    else:
        centre = -0.5 * slope * np.sign(deviation_at_50 - d)
    a = centre + rng.normal(0.0, plot_sd, n_plots)
    sg_c = 0.25 * d * np.exp(rng.normal(0.0, 0.2, n_plots))
    hidden = rng.random(n_plots) < no_deviation_share
    plot_ids = [f"p{i + 1:03d}" for i in range(n_plots)]
    reviewers = [f"r{i + 1:02d}" for i in range(n_reviewers)]
    plots = pd.DataFrame({
        "plot": pd.Series(plot_ids, dtype=object),
        "kind": pd.Series([kinds[i % len(kinds)] for i in range(n_plots)], dtype=object),
        "deviation": np.where(hidden, np.nan, d),
        "sg_c": np.where(hidden, np.nan, sg_c),
    })
    acceptability = dict(zip(plot_ids, a.tolist(), strict=True))
    strictness = dict(zip(reviewers, s.tolist(), strict=True))
    answers = simulate_answers(acceptability, strictness, seed=rng, repeat_share=repeat_share,
                               auto_share=auto_share, auto_shift=auto_shift, answer_share=answer_share)
    return SimulatedWorkshop(answers, plots, strictness, acceptability, float(deviation_at_50), float(slope))

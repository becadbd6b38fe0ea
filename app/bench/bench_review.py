"""Review workshop analysis: time of railval.core.review.analyse for 50 reviewers × 120 plots.

Simulated reviewers (:func:`railval.core.review.simulate_workshop`, seed 0) answer
``--plots`` plots each (first showings), plus hidden repeats of ``--repeats`` of them and
automatic-scaling showings of ``--auto`` of them. Timed in the same run (best of
``--repeat``, wall clock and CPU time of this process):

* the whole analysis as the CLI and the analysis page run it (``n_boot`` bootstrap
  replicates for the agreement intervals, default 1000; goal ≤ 5 s);
* baseline: the same analysis without bootstrap (``n_boot=0``);
* railval's fit of the Rasch-type model alone, and the ``krippendorff`` package's α next to
  railval's α on the same answers;
* with ``--glm`` also the same Rasch-type model fitted by statsmodels' GLM on plot and
  reviewer dummies (what a plain statsmodels script would do) — one call, it is slow.
"""

from __future__ import annotations

import argparse
import math
import time
import warnings

import numpy as np

from railval.core import lazy

#: deferred (railval.core.lazy): ``railval bench`` (the list) imports every benchmark module for its
#: docstring; what the benchmark runs loads when it runs
analyse = lazy.function("railval.core.review", "analyse")
fit_rasch = lazy.function("railval.core.review", "fit_rasch")
krippendorff_alpha_nominal = lazy.function("railval.core.review", "krippendorff_alpha_nominal")
simulate_workshop = lazy.function("railval.core.review", "simulate_workshop")
#: third-party libraries of the benchmark's own steps, loaded when they run
krippendorff = lazy.module("krippendorff")
sm = lazy.module("statsmodels.api")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--reviewers", type=int, default=50, help="reviewers (default 50)")
    parser.add_argument("--plots", type=int, default=120, help="plots answered by each (default 120)")
    parser.add_argument("--repeats", type=float, default=0.1, help="share of hidden repeats (default 0.1)")
    parser.add_argument("--auto", type=float, default=0.1,
                        help="share shown again at automatic scaling (default 0.1)")
    parser.add_argument("--boot", type=int, default=1000, help="bootstrap replicates (default 1000)")
    parser.add_argument("--repeat", type=int, default=3, help="repetitions, best is reported (default 3)")
    parser.add_argument("--glm", action="store_true",
                        help="also time the statsmodels GLM fit of the Rasch-type model (one call)")


def _best(func, repeat: int) -> tuple[float, float]:
    """Best wall-clock and best CPU time of ``repeat`` calls in s, after one warm-up call."""
    func()
    wall = cpu = math.inf
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        func()
        wall = min(wall, time.perf_counter() - t0)
        cpu = min(cpu, time.process_time() - c0)
    return wall, cpu


def run(args: argparse.Namespace) -> dict:
    rep = max(1, int(args.repeat))
    w = simulate_workshop(int(args.reviewers), int(args.plots), seed=0, strictness_sd=1.5,
                          repeat_share=float(args.repeats), auto_share=float(args.auto), auto_shift=0.5)
    answers, plots = w.answers, w.plots
    full = _best(lambda: analyse(answers, plots, n_boot=int(args.boot),
                                 threshold_boot=int(args.boot)), rep)
    no_boot = _best(lambda: analyse(answers, plots, n_boot=0, threshold_boot=0), rep)

    first = answers[~answers["repeat"] & (answers["scaling"] == "fixed")]
    r_idx = np.unique(first["reviewer"].to_numpy(), return_inverse=True)[1]
    p_idx = np.unique(first["plot"].to_numpy(), return_inverse=True)[1]
    y = first["answer"].to_numpy(dtype=float)
    n_r, n_p = int(r_idx.max()) + 1, int(p_idx.max()) + 1
    rasch = _best(lambda: fit_rasch(r_idx, p_idx, y, n_reviewers=n_r, n_plots=n_p), rep)
    glm_t = None
    if args.glm:
        design = np.zeros((y.size, n_p + n_r - 1))
        design[np.arange(y.size), p_idx] = 1.0
        for k in range(n_r - 1):
            design[r_idx == k, n_p + k] = -1.0
            design[r_idx == n_r - 1, n_p + k] = 1.0
        t0, c0 = time.perf_counter(), time.process_time()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sm.GLM(y, design, family=sm.families.Binomial()).fit()
        glm_t = (time.perf_counter() - t0, time.process_time() - c0)
    mat = np.full((n_r, n_p), np.nan)
    mat[r_idx, p_idx] = y
    alpha_pkg = _best(lambda: krippendorff.alpha(reliability_data=mat, level_of_measurement="nominal"), rep)
    alpha_own = _best(lambda: krippendorff_alpha_nominal(mat), rep)

    def ms(t: tuple[float, float]) -> dict:
        return {"wall_ms": round(1e3 * t[0], 1), "cpu_ms": round(1e3 * t[1], 1)}

    out = {
        "timing": f"best of {rep} after a warm-up; wall clock and CPU time of this process",
        "reviewers": int(args.reviewers),
        "plots": int(args.plots),
        "answers_total": len(answers),
        "first_answers": len(first),
        "bootstrap_replicates": int(args.boot),
        "analyse_full": ms(full),
        "analyse_full_within_5s": full[0] <= 5.0,
        "baseline_analyse_without_bootstrap": ms(no_boot),
        "rasch_fit_railval": ms(rasch),
        "krippendorff_alpha_railval": ms(alpha_own),
        "baseline_krippendorff_alpha_package": ms(alpha_pkg),
    }
    if glm_t is not None:
        out["baseline_rasch_fit_statsmodels_glm_one_call"] = ms(glm_t)
    return out

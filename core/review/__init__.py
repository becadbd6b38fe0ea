"""railval.core.review — statistics of expert review workshops (docs/workshops.md).

Reviewers answer Yes/No ("is the model validated for this signal?") on plots comparing
measurement and simulation, as in the DynoTRAIN workshop (Polach & Böttcher 2014 §3.2, §4.2,
Table 1). This package turns the answers into:

* :mod:`~railval.core.review.agreement` — Wilson interval, Fleiss κ, Krippendorff α (nominal),
  Gwet AC1 and the exact McNemar test, each from its paper;
* :mod:`~railval.core.review.rasch` — each reviewer's strictness on a latent scale
  (Rasch-type logistic model);
* :mod:`~railval.core.review.threshold` — the objective value (normalised deviation,
  Sprague–Geers C) at which a typical reviewer says Yes half of the time, model-free in the
  link, and its sensitivity to the link;
* :mod:`~railval.core.review.analysis` — :func:`analyse`, the whole analysis of one workshop;
* :mod:`~railval.core.review.simulate` — simulated reviewers of known strictness.

Pure computation: no database, no app, no I/O.
"""

from railval.core.review.agreement import (
    fleiss_kappa,
    gwet_ac1,
    gwet_ac1_two_raters,
    krippendorff_alpha_nominal,
    mcnemar_exact,
    wilson_interval,
)
from railval.core.review.analysis import WorkshopAnalysis, analyse
from railval.core.review.rasch import RaschFit, fit_rasch
from railval.core.review.simulate import (
    SimulatedWorkshop,
    simulate_answers,
    simulate_workshop,
    yes_probability,
)
from railval.core.review.threshold import (
    MonotoneThreshold,
    ThresholdFit,
    fit_threshold,
    link_sensitivity,
    monotone_threshold,
    yes_curve,
)

__all__ = [
    "MonotoneThreshold",
    "RaschFit",
    "SimulatedWorkshop",
    "ThresholdFit",
    "WorkshopAnalysis",
    "analyse",
    "fit_rasch",
    "fit_threshold",
    "fleiss_kappa",
    "gwet_ac1",
    "gwet_ac1_two_raters",
    "krippendorff_alpha_nominal",
    "link_sensitivity",
    "mcnemar_exact",
    "monotone_threshold",
    "simulate_answers",
    "simulate_workshop",
    "wilson_interval",
    "yes_curve",
    "yes_probability",
]

"""Pure parts of review workshops: plot-kind registry, round-number scaling, objective
deviation, reviewer order (railval.core.workshop)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from railval.core.errors import InvalidParameter
from railval.core.quantities import QUANTITIES
from railval.core.workshop import (
    PLOT_KINDS,
    AxisRange,
    Extent,
    decade_range,
    dv_over_limit,
    kind_scale,
    nice_range,
    nice_step,
    plot_deviation,
    plots_for,
    review_order,
)


@pytest.mark.parametrize(("span", "ticks", "step"), [
    (10.0, 5, 2.0), (7.3, 5, 2.0), (1.0, 5, 0.2), (0.37, 5, 0.1), (1234.0, 5, 250.0),
    (30.0, 5, 10.0), (0.012, 4, 0.005), (1e6, 5, 2e5),
])
def test_nice_step_is_one_two_two_and_half_or_five_times_a_power_of_ten(span, ticks, step):
    assert nice_step(span, ticks) == pytest.approx(step)


def test_nice_range_contains_the_data_on_whole_steps():
    rng = np.random.default_rng(1)
    for _ in range(300):
        lo = float(rng.normal(0, 10 ** rng.uniform(-3, 4)))
        hi = lo + float(10 ** rng.uniform(-3, 4))
        r = nice_range(lo, hi)
        assert r.lo <= lo and r.hi >= hi
        n = (r.hi - r.lo) / r.step
        assert abs(n - round(n)) < 1e-6 and 1 <= round(n) <= 10
        assert abs(r.lo / r.step - round(r.lo / r.step)) < 1e-6
        mantissa = r.step / 10 ** math.floor(math.log10(r.step))
        assert round(mantissa, 9) in (1.0, 2.0, 2.5, 5.0)


def test_nice_range_examples_computed_by_hand():
    # span 25.5 / 5 ticks = 5.1 → step 10; −17.3 → −20, 8.2 → 10
    assert nice_range(-17.3, 8.2) == AxisRange(-20.0, 10.0, 10.0)
    assert nice_range(61.0, 98.5) == AxisRange(60.0, 100.0, 10.0)
    assert nice_range(0.0, 1549.0) == AxisRange(0.0, 2000.0, 500.0)  # 1549 / 5 = 309.8 → 500
    assert nice_range(3.0, 3.0) == AxisRange(0.0, 6.0, 2.0)


def test_nice_range_refuses_bad_limits():
    with pytest.raises(InvalidParameter, match="below"):
        nice_range(2.0, 1.0)
    with pytest.raises(InvalidParameter, match="finite"):
        nice_range(0.0, float("nan"))


def test_decade_range_whole_decades_with_a_floor():
    assert decade_range(3e-5, 0.2) == AxisRange(1e-5, 1.0, 10.0, log=True)
    # values below hi·1e-6 are cut off at that floor
    r = decade_range(1e-20, 0.5)
    assert r.lo == pytest.approx(1e-7) and r.hi == 1.0


def test_kind_scale_is_one_range_for_every_plot_of_the_kind():
    extents = [Extent(0.0, 1549.0, -7.1, 6.2), Extent(0.0, 1910.0, -3.0, 9.4),
               Extent(0.0, 1200.0, -12.2, 1.0)]
    s = kind_scale("time", extents)
    assert s.x.lo == 0.0 and s.x.hi >= 1910.0 and s.y.lo <= -12.2 and s.y.hi >= 9.4
    assert (s.y.lo, s.y.hi, s.y.step) == (-15.0, 10.0, 5.0)
    p = kind_scale("psd", [Extent(0, 20, 1e-6, 0.03), Extent(0, 20, 2e-7, 0.4)])
    assert p.y.log and p.y.lo == pytest.approx(1e-7) and p.y.hi == 1.0 and p.x.hi == 20.0
    with pytest.raises(InvalidParameter):
        kind_scale("time", [])


def test_registry_default_set_matches_the_dynotrain_review_forms():
    coach = ([f"{k}_{p}" for k in ("Y", "Q") for p in ("w1L", "w1R", "w2L", "w2R", "w3L", "w3R", "w4L", "w4R")]
             + [f"{k}_{p}" for k in ("ay_cb", "az_cb", "ay_bg", "az_bg") for p in ("b1", "b2")])
    plots = plots_for(list(PLOT_KINDS), coach)
    time_plots = [p for p in plots if PLOT_KINDS[p[0]].domain == "time"]
    psd_plots = [p for p in plots if PLOT_KINDS[p[0]].domain == "psd"]
    # 12 wheel plots + 4 car body (the seed's 16) + 4 bogie frame; 4 PSDs
    assert len(time_plots) == 20 and len(psd_plots) == 4
    freight = [c for c in coach if "_bg_" not in c]
    assert len([p for p in plots_for(list(PLOT_KINDS), freight) if PLOT_KINDS[p[0]].domain == "time"]) == 16
    for k in PLOT_KINDS.values():
        assert all(q in QUANTITIES for q in k.quantities)
    with pytest.raises(InvalidParameter, match="unknown plot kind"):
        plots_for(["Y_time", "nope"], coach)


def test_plot_deviation_is_the_largest_normalised_difference_of_the_signals_quantities():
    limits = {q: QUANTITIES[q].std_limit(80.0) for q in QUANTITIES}
    measured = {("Y_qst", "w1L"): 10.0, ("Y_max", "w1L"): 30.0, ("ay_rms", "b1"): 0.2,
                ("Y_qst", "w1R"): -4.0}
    simulated = {("Y_qst", "w1L"): 12.0, ("Y_max", "w1L"): 20.0, ("ay_rms", "b1"): 0.35,
                 ("Y_qst", "w1R"): -5.0}
    dv = dv_over_limit(measured, simulated, limits)
    # hand: Y_qst (12−10)/5 = 0.4; Y_max (20−30)/9 = −1.111; ay_rms (0.35−0.2)/0.15 = 1.0
    # Y_qst w1R: D_v = (−5 − −4)·sign(−4) = +1 → 1/5 = 0.2
    assert dv[("Y_max", "w1L")] == pytest.approx(-10 / 9)
    assert dv[("Y_qst", "w1R")] == pytest.approx(0.2)
    assert plot_deviation("Y_time", "w1L", dv) == pytest.approx(10 / 9)
    assert plot_deviation("ay_cb_psd", "b1", dv) == pytest.approx(1.0)  # a PSD takes its signal's
    assert plot_deviation("ay_bg_time", "b1", dv) is None  # bogie: no EN quantity
    assert plot_deviation("Q_time", "w1L", dv) is None  # not evaluated


def test_review_order_each_plot_once_and_repeats_later():
    for seed in range(20):
        seq = review_order(120, seed, 0.1)
        firsts = [p for p, rep in seq if not rep]
        assert sorted(firsts) == list(range(120))
        reps = [(i, p) for i, (p, rep) in enumerate(seq) if rep]
        assert len(reps) == 12 and len({p for _, p in reps}) == 12
        for i, p in reps:
            first = seq.index((p, False))
            assert i > first
    assert review_order(50, 7) == review_order(50, 7)
    assert review_order(50, 7) != review_order(50, 8)
    assert review_order(10, 1, 0.0) == [(p, False) for p, _ in review_order(10, 1, 0.0)]
    with pytest.raises(InvalidParameter):
        review_order(10, 1, 1.5)


def test_scale_keys_group_scales_and_flat_plots():
    """Zone scaling: one range per (kind, zone); workshop scaling: one per kind. A PSD is
    flat when it spans less than a tenth of its decades."""
    from railval.core.workshop import (
        AxisRange,
        check_scaling,
        group_scales,
        is_flat,
        scale_key,
        span_share,
    )

    assert scale_key("Y_time", 3, "zone") == "Y_time zone 3" and scale_key("Y_time", 3, "workshop") == "Y_time"
    with pytest.raises(InvalidParameter, match="scaling must be one of zone, workshop"):
        check_scaling("auto")
    ex = [("a", Extent(0, 500, -2, 3)), ("a", Extent(0, 800, -1, 1)), ("b", Extent(0, 300, -40, 55))]
    sc = group_scales({"a": "time", "b": "time"}, ex)
    assert (sc["a"].y.lo, sc["a"].y.hi, sc["a"].x.hi) == (-2.0, 3.0, 800.0)
    assert (sc["b"].y.lo, sc["b"].y.hi) == (-40.0, 60.0)
    decades = AxisRange(1e-6, 1e-1, 10.0, log=True)          # 5 decades
    assert span_share(Extent(0, 20, 1e-4, 1e-3), decades) == pytest.approx(0.2)
    assert is_flat(Extent(0, 20, 1e-4, 2e-4), decades) and not is_flat(Extent(0, 20, 1e-4, 1e-3), decades)

"""Plausible ranges of the simulator's parameters: every effect and template parameter carries a
physically plausible range inside its bounds, with a source (docs/simulator.md)."""

from __future__ import annotations

import pytest
from railval.core.sim.effects import EFFECTS
from railval.core.sim.params import Param, plausibility
from railval.core.sim.synth import hidden_defaults
from railval.core.sim.vehicles import TEMPLATES


def _all_params():
    for e in EFFECTS.values():
        for p in e.parameters.values():
            yield f"effect {e.id}", p
    for t, params in TEMPLATES.items():
        for p in params:
            yield f"template {t}", p


@pytest.mark.parametrize(("owner", "p"), list(_all_params()), ids=lambda x: x if isinstance(x, str) else x.name)
def test_every_parameter_has_a_plausible_range_inside_its_bounds_with_a_source(owner, p):
    assert p.plausible is not None, (owner, p.name)
    lo, hi = p.plausible
    assert p.lower <= lo <= hi <= p.upper, (owner, p.name)
    assert len(p.plausible_source) > 10, (owner, p.name)
    d = p.to_dict()
    assert d["plausible"] == [lo, hi] and d["plausible_source"] == p.plausible_source


def test_template_defaults_are_plausible():
    for t, params in TEMPLATES.items():
        for p in params:
            assert p.is_plausible(p.default), (t, p.name, p.default, p.plausible)


def test_plausible_range_must_lie_inside_bounds_and_plausibility_report():
    with pytest.raises(ValueError, match="plausible range"):
        Param("x", "-", 1.0, 0.0, 2.0, "x", plausible=(0.5, 3.0))
    p = Param("x", "-", 1.0, 0.0, 2.0, "x", plausible=(0.5, 1.5), plausible_source="test")
    rep = plausibility((p,), {"x": 1.8, "unknown": 1.0})
    assert rep == {"x": {"value": 1.8, "plausible": [0.5, 1.5], "inside": False, "source": "test"}}
    assert Param("y", "-", 1.0, 0.0, 2.0, "y").plausible_range == (0.0, 2.0)
@pytest.mark.parametrize("template", ["coach", "wagon"])
def test_hidden_defaults_are_plausible(template):
    for eid, values in hidden_defaults(template).items():
        for name, v in values.items():
            assert EFFECTS[eid].parameters[name].is_plausible(v), (template, eid, name, v)




#: Manchester Benchmark vehicle 1 (Iwnicki 1998, VSD 30:3-4) as listed independently in the open
#: TTB-2D train–track–bridge model (Cantero, NTNU; its "Manchester Benchmark vehicle" file, a 2-D
#: reduction: per-side values there are doubled, half-distances given as 9.5 m and 1.28 m)
MANCHESTER_PUBLISHED = {
    "m_carbody": 32000.0, "I_pitch_carbody": 1.97e6, "bogie_centres": 2 * 9.5, "m_bogie": 2615.0,
    "I_pitch_bogie": 1476.0, "wheelbase": 2 * 1.28, "m_wheelset": 1813.0, "k_primary_z": 1200e3,
    "c_primary_z": 4e3, "k_secondary_z": 430e3, "c_secondary_z": 20e3,
}


def test_manchester_benchmark_values_agree_with_a_published_listing():
    """Every coach value marked [MB] equals the benchmark's published figure; every value not
    in that listing is marked as an assumption ([MB?], [typ]) or names another source."""
    coach = {p.name: p for p in TEMPLATES["coach"]}
    marked = {n for n, p in coach.items() if p.source == "[MB]"}
    assert marked == set(MANCHESTER_PUBLISHED), marked ^ set(MANCHESTER_PUBLISHED)
    for name, value in MANCHESTER_PUBLISHED.items():
        assert coach[name].default == pytest.approx(value, rel=1e-12), name
    for name, p in coach.items():
        if p.source.startswith(("[MB?]", "[typ]")):
            assert "assumption" in p.source, (name, p.source)

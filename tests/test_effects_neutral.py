"""An effect at its neutral values (``Effect.neutral``, core/sim/effects.py) simulates bit for
bit as without it, so a diagnosis reuses the configuration's own run there instead of
simulating again (app/services/diagnosis_ranking.py ``_tasks``); a value next to the neutral
one does change the signals (the comparison can fail)."""

from __future__ import annotations

import numpy as np
import pytest

from railval.app.services.diagnosis import diagnosis_simulations
from railval.core.sim import TrackSection, VehicleModel, simulate_section
from railval.core.sim.effects import EFFECTS, is_neutral

NEUTRAL = sorted(e for e, spec in EFFECTS.items() if spec.neutral)


def _track() -> TrackSection:
    return TrackSection("N", speed_kmh=90, radius_m=500, cant_mm=100, straight_in_m=60, transition_in_m=40,
                        curve_m=120, transition_out_m=40, straight_out_m=60, seed=3)


def _run(template: str, effects: dict) -> dict[str, np.ndarray]:
    return simulate_section(VehicleModel(template), _track(), effects, fs_out=100.0).channels


def _same(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)


def test_the_registry_declares_the_neutral_effects():
    assert NEUTRAL == ["friction_damping", "parasitic_yaw_stiffness", "track_level_lateral", "track_level_vertical"]


@pytest.mark.parametrize("template", ["coach", "wagon"])
def test_an_effect_at_its_neutral_values_simulates_as_without_it(template):
    plain = _run(template, {})
    for e in NEUTRAL:
        spec = EFFECTS[e]
        if template not in spec.templates:
            continue
        point = {k: float(p.default) for k, p in spec.parameters.items()} | dict(spec.neutral)
        assert is_neutral(spec, point)
        assert _same(_run(template, {e: point}), plain), e
        # next to the neutral value the effect acts: the comparison above can fail
        name, v = next(iter(spec.neutral.items()))
        moved = {**point, name: v + 0.1 * (spec.parameters[name].upper - spec.parameters[name].lower)}
        assert not is_neutral(spec, moved)
        assert not _same(_run(template, {e: moved}), plain), e


def test_the_announced_simulations_leave_the_neutral_points_out():
    # parasitic_yaw_stiffness at 2 values: 0 (neutral), 3000 and the default 600 → 2 runs
    assert diagnosis_simulations(["parasitic_yaw_stiffness"], 2, "coach", parameters=False) == 1 + 2
    assert diagnosis_simulations(["conicity"], 2, "coach", parameters=False) == 1 + 3

"""Tests of core.calibration: optimiser, validation objective, coach modal model and the
[ref 3] modal calibration (identify with SSI-COV, pair by MAC, fit frequencies and MAC)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import eigh

from railval.app.services.batch import BatchExecutor
from railval.core.calibration import (
    COACH_MODAL_DEFAULTS,
    ParameterSpec,
    calibrate,
    calibrate_modal,
    coach_vertical_modes,
    max_evaluations,
    modal_objective,
    validation_objective,
)
from railval.core.errors import InvalidParameter
from railval.core.modal import ssi_cov
from tests.test_modal import simulate_accelerations


def _quadratic(p):
    # minimum 0 at a = 1.5, b = −0.25 (by construction)
    return (p["a"] - 1.5) ** 2 + 10 * (p["b"] + 0.25) ** 2


def test_calibrate_finds_known_minimum_and_reports_progress():
    seen = []
    specs = [ParameterSpec("a", 0.0, 3.0, start=0.5), ParameterSpec("b", -1.0, 1.0, start=0.5)]
    res = calibrate(_quadratic, specs, seed=1, progress=lambda s, f, i: seen.append((s, f)))
    assert res.parameters["a"] == pytest.approx(1.5, abs=1e-3)
    assert res.parameters["b"] == pytest.approx(-0.25, abs=1e-3)
    assert res.objective_start == pytest.approx(1.0 + 10 * 0.5625)
    assert res.objective < 1e-5 and res.n_evaluations > 10
    assert seen[-1] == ("done", 1.0) and seen[0][0] == "global"
    d = res.to_dict()
    assert d["bounds"]["a"] == [0.0, 3.0] and d["objective"] == res.objective
    # seeded → reproducible; a map-like executor evaluates generations (deferred updating)
    again = calibrate(_quadratic, specs, seed=1)
    assert again.parameters == res.parameters
    with BatchExecutor("serial") as ex:
        par = calibrate(_quadratic, specs, seed=1, workers=ex)
    assert par.parameters["a"] == pytest.approx(1.5, abs=1e-3)


@pytest.mark.parametrize("popsize,maxiter,polish_maxfev", [(3, 1, 4), (6, 3, 2), (2, 2, 0)])
def test_objective_calls_stay_within_the_announced_budget(popsize, maxiter, polish_maxfev):
    calls = []

    def counted(p):
        calls.append(p)
        return _quadratic(p)

    specs = [ParameterSpec("a", 0.0, 3.0, start=0.5), ParameterSpec("b", -1.0, 1.0, start=0.5)]
    res = calibrate(counted, specs, seed=2, popsize=popsize, maxiter=maxiter, tol=0.0,
                    polish_maxfev=polish_maxfev)
    # scipy keeps at least 5 population members: max(5, popsize·n) per generation
    bound = 1 + max(5, popsize * 2) * (maxiter + 1) + polish_maxfev
    assert max_evaluations(2, popsize, maxiter, polish_maxfev) == bound
    assert len(calls) == res.n_evaluations + 1 <= bound  # + 1: the start point
    assert res.objective <= res.objective_start


def test_parameter_spec_and_calibrate_validate_inputs():
    with pytest.raises(InvalidParameter, match="lower < upper"):
        ParameterSpec("k", 2.0, 1.0)
    with pytest.raises(InvalidParameter, match="outside bounds"):
        ParameterSpec("k", 0.0, 1.0, start=2.0)
    with pytest.raises(InvalidParameter):
        calibrate(_quadratic, [])


def test_validation_objective_hand_values():
    # max(0.5, 1.2)² + max(2, 1)² = 1.44 + 4 = 5.44
    assert validation_objective({"a": 0.5, "b": -2.0}, {"a": 1.2, "b": 1.0}) == pytest.approx(5.44)
    # soft max ≥ max and → max as s → 0; equal arguments: max + s·ln 2
    assert validation_objective({"a": 1.0}, {"a": 1.0}, smooth=0.1) == pytest.approx((1 + 0.1 * math.log(2)) ** 2)
    assert validation_objective({"a": 0.5}, {"a": 1.2}, smooth=1e-4) == pytest.approx(1.44, rel=1e-6)


def test_coach_modes_closed_form_with_rigid_primary():
    # k_p → ∞: bogies fixed, body bounce √(2·2k_s/m)/2π and pitch √(2·2k_s·a²/I)/2π
    f, shapes = coach_vertical_modes({"k_primary_z": 1e12})
    ks = 2 * COACH_MODAL_DEFAULTS["k_secondary_z"]
    a = COACH_MODAL_DEFAULTS["bogie_half_distance"]
    bounce = math.sqrt(2 * ks / COACH_MODAL_DEFAULTS["m_carbody"]) / (2 * math.pi)
    pitch = math.sqrt(2 * ks * a * a / COACH_MODAL_DEFAULTS["I_pitch_carbody"]) / (2 * math.pi)
    np.testing.assert_allclose(sorted(f[:2]), sorted([bounce, pitch]), rtol=1e-6)
    # bounce: both sensors in phase; pitch: opposite
    k_b = int(np.argmin(np.abs(f - bounce)))
    assert shapes[0, k_b] == pytest.approx(shapes[1, k_b])
    with pytest.raises(InvalidParameter, match="unknown"):
        coach_vertical_modes({"nope": 1.0})


def test_modal_objective_zero_for_identical_modes():
    f, s = coach_vertical_modes()
    J, pairs = modal_objective(f, s, f[:2], s[:, :2])
    assert J == pytest.approx(0.0, abs=1e-12)
    assert [(i, j) for i, j, _ in pairs] == [(0, 0), (1, 1)]


def test_modal_calibration_recovers_parameters_from_exact_modes():
    truth = {"k_secondary_z": 430e3 * 1.15, "I_pitch_carbody": 1.97e6 * 0.9}
    f, s = coach_vertical_modes(truth)
    specs = [ParameterSpec("k_secondary_z", 301e3, 559e3, "N/m"),
             ParameterSpec("I_pitch_carbody", 1.379e6, 2.561e6, "kg·m²")]
    res = calibrate_modal(f[:2], s[:, :2], specs, seed=0)
    assert res.mean_abs_error_before_pct > 3.0
    assert res.mean_abs_error_after_pct < 0.05
    for k, v in truth.items():
        assert res.calibration.parameters[k] == pytest.approx(v, rel=0.01)
    assert len(res.to_pandas()) == 2 and res.to_dict()["modes"][0]["mac_after"] > 0.99


def test_modal_calibration_from_ssi_identified_modes():
    """Truth coach (secondary stiffness +12 %), white-noise forces on every DOF,
    accelerations above both bogies → SSI-COV → calibration recovers k_secondary_z within 3 %
    (bounded by the SSI frequency error, ~0.5 % at this record length)."""
    p = dict(COACH_MODAL_DEFAULTS)
    p["k_secondary_z"] *= 1.12
    a, ks, kp = p["bogie_half_distance"], 2 * p["k_secondary_z"], 4 * p["k_primary_z"]
    M = np.diag([p["m_carbody"], p["I_pitch_carbody"], p["m_bogie"], p["m_bogie"]])
    K = np.array([[2 * ks, 0, -ks, -ks], [0, 2 * ks * a * a, -ks * a, ks * a],
                  [-ks, -ks * a, ks + kp, 0], [-ks, ks * a, 0, ks + kp]])
    w2, V = eigh(K, M)
    C = M @ V @ np.diag(2 * 0.05 * np.sqrt(w2)) @ V.T @ M  # 5 % modal damping
    acc = simulate_accelerations(M, K, C, 40.0, 24_000, seed=5)
    body = acc[:, :2] @ np.array([[1.0, 1.0], [a, -a]])  # z_c ± a·θ_c at the two sensors
    ident = ssi_cov(body, 40.0, f_min=0.5, f_max=3.0, block_rows=40, max_order=20)
    assert len(ident.modes) >= 2
    res = calibrate_modal(ident.frequencies[:2], ident.shapes[:, :2],
                          [ParameterSpec("k_secondary_z", 301e3, 559e3, "N/m")], seed=0)
    assert res.calibration.parameters["k_secondary_z"] == pytest.approx(p["k_secondary_z"], rel=0.03)
    assert res.mean_abs_error_after_pct < res.mean_abs_error_before_pct


def _coach_body_accelerations(n: int, fs: float, k_factor: float, seed: int) -> np.ndarray:
    """Accelerations above bogie 1 and 2 of the 4-DOF vertical coach (k_secondary_z scaled by
    ``k_factor``, 5 % modal damping) under white-noise forces on every DOF."""
    p = dict(COACH_MODAL_DEFAULTS)
    p["k_secondary_z"] *= k_factor
    a, ks, kp = p["bogie_half_distance"], 2 * p["k_secondary_z"], 4 * p["k_primary_z"]
    M = np.diag([p["m_carbody"], p["I_pitch_carbody"], p["m_bogie"], p["m_bogie"]])
    K = np.array([[2 * ks, 0, -ks, -ks], [0, 2 * ks * a * a, -ks * a, ks * a],
                  [-ks, -ks * a, ks + kp, 0], [-ks, ks * a, 0, ks + kp]])
    w2, V = eigh(K, M)
    C = M @ V @ np.diag(2 * 0.05 * np.sqrt(w2)) @ V.T @ M
    acc = simulate_accelerations(M, K, C, fs, n, seed=seed)
    return acc[:, :2] @ np.array([[1.0, 1.0], [a, -a]])


def test_modal_service_and_cli_on_an_imported_campaign(tmp_path, capsys):
    """Campaign whose measured az_cb come from a coach with k_secondary_z +12 %: the modal
    service identifies the bounce and pitch modes from all sections and the calibration moves
    k_secondary_z to the truth (within 3 %); the CLI prints the same as JSON."""
    import json

    from railval.app.cli import main
    from railval.app.services.modal import modal
    from railval.db.engine import connect
    from railval.db.importer import import_campaign
    from railval.db.io import read_table, write_table
    from tests.factories import write_demo_campaign

    manifest = write_demo_campaign(tmp_path / "camp", n_sections=12, name="modal-demo", fs=50.0)
    spec = json.loads(manifest.read_text())
    for k, sec in enumerate(spec["sections"]):
        path = manifest.parent / sec["measured"]
        cols = read_table(path)
        body = _coach_body_accelerations(cols["time_s"].size, 50.0, 1.12, seed=100 + k)
        cols["az_cb_b1"], cols["az_cb_b2"] = body[:, 0], body[:, 1]
        write_table(path, cols)
    url = f"sqlite:///{tmp_path / 'modal.db'}"
    database = connect(url)
    database.init()
    import_campaign(database, manifest.parent)
    out = modal(database, "modal-demo", calibrate_params=["k_secondary_z"])
    freqs = [m["freq_hz"] for m in out["identification"]["modes"]]
    f_true, _ = coach_vertical_modes({"k_secondary_z": 430e3 * 1.12})
    for f in f_true[:2]:
        assert min(abs(x - f) for x in freqs) < 0.03 * f
    cal = out["calibration"]
    assert cal["parameters_after"]["k_secondary_z"] == pytest.approx(430e3 * 1.12, rel=0.03)
    assert cal["mean_abs_error_after_pct"] < cal["mean_abs_error_before_pct"]
    database.dispose()
    assert main(["--db", url, "modal", "modal-demo", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert len(doc["identification"]["modes"]) >= 2 and doc["stabilisation"]


def _log_bowl(p):
    # minimum 0 at k = 0.3 in a box spanning 0.2 … 50 (2.4 decades)
    return (math.log10(p["k"]) - math.log10(0.3)) ** 2


def test_log_scale_parameter_is_searched_in_log10():
    spec = ParameterSpec("k", 0.2, 50.0, "MN/m", start=4.0, log=True)
    assert spec.to_search(10.0) == pytest.approx(1.0) and spec.from_search(1.0) == pytest.approx(10.0)
    res = calibrate(_log_bowl, [spec], seed=0, popsize=5, maxiter=5, polish_maxfev=20)
    assert res.parameters["k"] == pytest.approx(0.3, rel=0.02)
    assert res.to_dict()["log_scale"] == ["k"]
    with pytest.raises(InvalidParameter, match="lower > 0"):
        ParameterSpec("k", 0.0, 1.0, log=True)


def test_start_on_the_bounds_is_accepted():
    # (start on both lower bounds; scipy rejects an x0 that rounds outside its unit cube)
    specs = [ParameterSpec("a", 5.0, 16.0, start=5.0), ParameterSpec("b", 0.005, 0.1, start=0.005)]
    res = calibrate(lambda p: (p["a"] - 5.0) ** 2 + (p["b"] - 0.005) ** 2, specs, seed=0, maxiter=3)
    assert res.objective_start == pytest.approx(0.0) and res.objective <= 1e-12


def test_service_objective_is_inf_where_the_simulation_diverges(monkeypatch):
    """A diverged simulation (non-finite channel) is the search's worst point, not an abort;
    any other signal error still raises."""
    from railval.app.services import calibration as svc
    from railval.core.errors import InvalidSignal

    obj = svc._Objective(ctx=None, base_effects={}, base_params={}, targets=[("conicity", "conicity")])

    def diverged(task):
        raise InvalidSignal("section S09: channel Y_w1L holds non-finite values (nan)")

    monkeypatch.setattr(svc, "evaluate_effects", diverged)
    assert obj({"conicity.conicity": 0.3}) == math.inf

    def broken(task):
        raise InvalidSignal("section S09: distance_m must be strictly increasing")

    monkeypatch.setattr(svc, "evaluate_effects", broken)
    with pytest.raises(InvalidSignal):
        obj({"conicity.conicity": 0.3})


def test_start_values_put_a_parameter_candidate_under_model_and_name_a_malformed_one():
    """The app sends a template-parameter candidate's start as ``{"model.P": {"P": v}}``, the
    CLI as ``{"model": {"P": v}}``; both reach the fit as ``start["model"]["P"]``."""
    from railval.app.services.calibration import _start_values

    got = _start_values({"model.k_z": {"k_z": 2}, "friction_damping": {"mu": 0.3}})
    assert got == {"friction_damping": {"mu": 0.3}, "model": {"k_z": 2.0}}
    assert _start_values({"model": {"k_z": 1.5}}) == {"model": {"k_z": 1.5}}
    assert _start_values(None) == {}
    with pytest.raises(InvalidParameter, match="start value of 'model.k_z'.*got keys \\['x'\\]"):
        _start_values({"model.k_z": {"x": 2.0}})

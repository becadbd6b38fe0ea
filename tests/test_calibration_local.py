"""Tests of the local calibration (core.calibration.calibrate_local): scan or start, then
bounded trust-region least squares (Branch, Coleman & Li 1999) on the residual vector of the
DynoTRAIN quantities, with the stopping tolerance stated in the result and the CLI JSON."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.optimize import least_squares

from railval.app.services.batch import BatchExecutor
from railval.core.calibration import ParameterSpec, validation_objective, validation_residuals
from railval.core.calibration_local import calibrate_local
from railval.core.errors import InvalidParameter


def _res(p):
    # overdetermined, linear: minimum computed independently by scipy below
    a, b = p["a"], p["b"]
    return np.array([a - 0.37, 2 * (a - 0.37) + 0.1 * (b - 3.0), 0.5 * (b - 3.0) + 0.05])


def _bimodal(p):
    # two wells: a shallow local one at x = 1 (cost 0.25), the global one at x = 8 (cost 0)
    x = p["x"]
    return np.array([min(0.3 * abs(x - 8.0), 0.5 + 0.5 * abs(x - 1.0))])


def test_local_fit_matches_scipy_least_squares_and_states_tolerance():
    specs = [ParameterSpec("a", 0.0, 1.0), ParameterSpec("b", 1.0, 5.0)]
    res = calibrate_local(_res, specs)
    ref = least_squares(lambda x: _res({"a": x[0], "b": x[1]}), [0.5, 3.0], bounds=([0, 1], [1, 5]),
                        xtol=1e-12, ftol=1e-12, gtol=1e-12)
    assert [res.parameters["a"], res.parameters["b"]] == pytest.approx(ref.x, abs=1e-3)
    assert res.objective == pytest.approx(2 * ref.cost, abs=1e-6)
    assert res.method == "local" and res.converged
    d = res.to_dict()
    assert d["tolerance"]["stopped_by"] in {"ftol", "xtol", "gtol", "ftol and xtol"}
    assert {"ftol", "xtol", "gtol", "max_nfev"} <= set(d["tolerance"])
    assert d["tolerance"]["stopped_by"] in d["message"]
    assert res.n_evaluations <= 30


def test_log_parameter_converges_in_few_evaluations_and_batches_in_workers():
    spec = [ParameterSpec("k", 0.5, 8.0, log=True)]
    res = calibrate_local(lambda p: np.array([np.log(p["k"] / 2.0)]), spec)
    assert res.parameters["k"] == pytest.approx(2.0, rel=1e-3)
    assert res.n_evaluations <= 12
    with BatchExecutor(None, 2) as ex:
        par = calibrate_local(_LogResidual(), spec, workers=ex)
    assert par.parameters["k"] == pytest.approx(res.parameters["k"], rel=1e-6)


class _LogResidual:
    def __call__(self, p):
        return np.array([np.log(p["k"] / 2.0)])


def test_bad_start_never_beats_the_scan():
    """A start in the shallow well: trf alone stays there; the result keeps the scan's better point."""
    spec = [ParameterSpec("x", 0.0, 10.0, start=1.0)]
    alone = least_squares(lambda x: _bimodal({"x": x[0]}), [1.0], bounds=([0.0], [10.0]))
    assert 2 * alone.cost > 0.2  # scipy from the bad start: the local well
    res = calibrate_local(_bimodal, spec)
    assert res.parameters["x"] == pytest.approx(8.0, abs=0.05)
    assert res.objective < 0.01 and res.objective_start == pytest.approx(0.25)
    assert res.tolerance["start_from"].startswith("scan")


def test_diverged_points_are_worst_not_fatal_and_bad_input_is_refused():
    spec = [ParameterSpec("x", 0.0, 4.0)]
    res = calibrate_local(lambda p: np.array([np.inf if p["x"] > 3 else p["x"] - 1.0]), spec)
    assert res.parameters["x"] == pytest.approx(1.0, abs=1e-3)
    with pytest.raises(InvalidParameter, match="at least one parameter"):
        calibrate_local(_res, [])


def test_residual_vector_squares_to_the_validation_objective():
    m = {"Q_max": 0.5, "Y_max": -2.0, "ay_rms": 0.3}
    s = {"Q_max": 1.0, "Y_max": 0.1, "ay_rms": 0.7}
    r = validation_residuals(m, s)
    assert r.tolist() == [1.0, 2.0, 0.7]
    assert float(r @ r) == pytest.approx(validation_objective(m, s))


def test_cli_split_hidden_friction_fits_truth_and_reports_tolerance(tmp_path, capsys):
    """Hidden friction (synthetic campaign, truth read from --reveal only after the fit):
    the default method recovers the breakaway force within 20 % on 8 fit sections and the
    JSON states the tolerance that stopped it; the held-out error is no worse than --global's."""
    from railval.app.cli import main
    from tests.test_hidden_effect import make_campaign

    database, truth = make_campaign(tmp_path, ["friction_damping"])
    out = {}
    for name, extra in (("local", []), ("global", ["--global"])):
        capsys.readouterr()
        assert main(["--db", database.url, "calibrate", "hidden", "--config", "baseline",
                     "--effect", "friction_damping", "--params", "friction_damping.force_kN",
                     "--as", f"cal_{name}", "--split", "--json", *extra]) == 0
        out[name] = json.loads(capsys.readouterr().out)
    loc = out["local"]
    assert loc["method"] == "local" and out["global"]["method"] == "global"
    assert loc["tolerance"]["stopped_by"] in {"ftol", "xtol", "gtol", "ftol and xtol"}
    assert loc["converged"] is True
    fitted = loc["parameters"]["friction_damping.force_kN"]
    assert fitted == pytest.approx(truth["hidden_effects"]["friction_damping"]["force_kN"], rel=0.2)
    held = [o["lineage"][-1]["held_out"]["max_error"] for o in (loc, out["global"])]
    assert held[0] <= held[1] + 0.02, held
    assert loc["n_evaluations"] < out["global"]["n_evaluations"]


class _Counted:
    """A residual that counts its own calls (each distinct evaluation of the fit calls it once)."""

    def __init__(self, f):
        self.f, self.calls = f, 0

    def __call__(self, p):
        self.calls += 1
        return self.f(p)


def _rosenbrock(p):
    # curved valley: trf needs many steps from a far start, so a small budget is spent
    return np.array([10 * (p["b"] - p["a"] ** 2), 1 - p["a"]])


def test_evaluation_bound_holds_when_the_budget_is_spent():
    """local_max_evaluations: scan (5 or 4n+1) + start + max_nfev·(1 + n), by hand."""
    from railval.core.calibration_local import local_max_evaluations

    assert local_max_evaluations(1) == 5 + 1 + 30 * 2
    assert local_max_evaluations(2) == 9 + 1 + 30 * 3
    assert local_max_evaluations(3, max_nfev=10, start=False) == 13 + 10 * 4
    with pytest.raises(InvalidParameter, match="at least 1"):
        local_max_evaluations(0)
    for nfev in (2, 4, 8):
        f = _Counted(_rosenbrock)
        specs = [ParameterSpec("a", -2.0, 2.0, start=-1.9), ParameterSpec("b", -1.0, 4.0, start=3.9)]
        res = calibrate_local(f, specs, max_nfev=nfev, ftol=1e-12, xtol=1e-12, gtol=1e-12)
        assert res.n_evaluations == f.calls  # every distinct evaluation counted
        assert res.tolerance["stopped_by"] == "evaluation budget (max_nfev) spent"
        assert f.calls <= local_max_evaluations(2, max_nfev=nfev)
        assert f.calls > local_max_evaluations(2, max_nfev=nfev) - 2 * nfev  # the bound is not loose by more

"""A configuration or vehicle carrying parameters the built-in simulator's template does not
know (an external model's names) is refused by the diagnosis and the calibration before any
simulation, naming the record and the names (app/services/campaign_context.py)."""

from __future__ import annotations

import dataclasses
import json

import pytest

from railval.app.services.calibration import calibrate
from railval.app.services.diagnosis import diagnose
from railval.core.errors import InvalidParameter
from railval.db import repo
from railval.db.importer import import_campaign
from tests.factories import write_demo_campaign


@pytest.fixture
def external(sqlite_database, tmp_path):
    manifest_path = write_demo_campaign(tmp_path / "c", n_sections=2, fmt="csv", seed=3, name="ext")
    m = json.loads(manifest_path.read_text())
    m["configurations"][0]["parameters"] = {"qs": 1.07, "c_yaw_damper": 2.0e5, "guide": 1.1}
    manifest_path.write_text(json.dumps(m))
    import_campaign(sqlite_database, manifest_path.parent)
    return sqlite_database


def _no_runs(database):
    with database.session() as s:
        return repo.row_counts(s)


def test_diagnosis_names_the_configuration_and_its_unknown_parameters(external):
    before = _no_runs(external)
    with pytest.raises(InvalidParameter) as info:
        diagnose(external, "ext", "baseline")
    msg = str(info.value)
    assert msg.startswith("configuration 'baseline' has parameters the built-in simulator's "
                          "vehicle template 'coach' does not know: 'guide', 'qs';")
    assert "c_yaw_damper" not in msg  # a template parameter is not named
    assert _no_runs(external) == before


def test_calibration_refuses_the_same_configuration(external):
    before = _no_runs(external)
    with pytest.raises(InvalidParameter, match="configuration 'baseline' has parameters .* 'guide', 'qs'"):
        calibrate(external, "ext", "baseline", ["wheel_rail_friction"], "fitted")
    assert _no_runs(external) == before


def test_the_template_parameters_alone_are_accepted(sqlite_database, tmp_path):
    """Planted contrast: the same campaign with template parameters only passes the check
    (the diagnosis then runs; its progress reaches the simulation)."""
    from railval.app.services.campaign_context import check_model_parameters, load_context

    manifest_path = write_demo_campaign(tmp_path / "c", n_sections=2, fmt="csv", seed=3, name="ok")
    import_campaign(sqlite_database, manifest_path.parent)
    with sqlite_database.session() as s:
        ctx = load_context(s, "ok")
    check_model_parameters(ctx, "baseline", {"c_yaw_damper": 2.0e5, "model.mu_nominal": 0.4})
    with pytest.raises(InvalidParameter, match="the campaign's vehicle has parameters .* 'wheelbase_m'"):
        check_model_parameters(dataclasses.replace(ctx, vehicle={
            **ctx.vehicle, "parameters": {"wheelbase_m": 2.5}}), "baseline", {})

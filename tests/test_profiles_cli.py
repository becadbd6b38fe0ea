"""Measured profiles on the command line (docs/simulator.md "Contact geometry as data"):
``railval simulate CAMPAIGN --config NAME --rrd FILE`` stores the Δr(y) table with the
configuration and simulates on it; a bad file is refused naming the file and the line with the
database unchanged; the diagnosis of a configuration with a table leaves the conicity out with
the reason."""

from __future__ import annotations

import json

import numpy as np
import pytest

from railval.app.cli import main
from railval.app.services.diagnosis_ranking import profile_skipped

GOOD = "# worn pair, measured\ny_mm,delta_r_mm\n0,0\n2.5,0.125\n2.6,2.125\n6,2.4\n7.5,3.6\n12,17.1\n"


def _run(capsys, *argv: str) -> tuple[int, str, str]:
    capsys.readouterr()
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def _state(database) -> tuple[list, int]:
    from sqlalchemy import func, select

    from railval.db.models import AuditEvent, Configuration

    with database.session() as s:
        confs = sorted((c.name, json.dumps(c.parameters, sort_keys=True)) for c in s.scalars(select(Configuration)))
        return confs, s.scalar(select(func.count()).select_from(AuditEvent))


@pytest.mark.parametrize("text,match", [
    ("y_mm,delta_r\n0,0\n1,1\n2,2\n", "line 1: missing column 'delta_r_mm'"),
    ("y_mm,delta_r_mm\n0,0\n2,0.5\n1.5,0.7\n3,1\n", "line 4: y_mm = 1.5 does not increase"),
    ("y_mm,delta_r_mm\n0,0\n2,0.5\n3,99\n", "line 4: field 'delta_r_mm' = 99.0 is outside [−40, 40] mm"),
])
def test_a_bad_profile_file_is_refused_and_the_database_is_unchanged(database, tmp_path, capsys, text, match):
    from tests.factories import write_demo_campaign

    write_demo_campaign(tmp_path / "c", n_sections=1, fmt="parquet")
    assert _run(capsys, "--db", database.url, "import", str(tmp_path / "c"))[0] == 0
    before = _state(database)
    bad = tmp_path / "worn.csv"
    bad.write_text(text, encoding="utf-8")
    code, _, err = _run(capsys, "--db", database.url, "simulate", "demo", "--config", "worn", "--rrd", str(bad))
    assert code == 2
    assert err.strip().startswith(f"railval simulate: error: contact geometry file 'worn.csv', {match}")
    assert _state(database) == before
    code, _, err = _run(capsys, "--db", database.url, "simulate", "demo", "--config", "worn", "--rrd",
                        str(tmp_path / "missing.csv"))
    assert code == 2 and "contact geometry file" in err and "missing.csv" in err and "cannot be read" in err
    assert _state(database) == before


def test_simulate_with_measured_profiles_stores_the_table_and_the_diagnosis_skips_conicity(sqlite_database, tmp_path,
                                                                                           capsys):
    from railval.app.services.diagnosis import diagnose
    from railval.app.services.synth import synth
    from railval.db import repo

    db = sqlite_database
    synth(db, name="p", hidden=["friction_damping"], n_sections=12)
    f = tmp_path / "worn.csv"
    f.write_text(GOOD, encoding="utf-8")
    code, out, err = _run(capsys, "--db", db.url, "simulate", "p", "--config", "worn", "--parent", "baseline",
                          "--rrd", str(f), "--json")
    assert code == 0, err
    doc = json.loads(out)
    table = doc["parameters"]["contact_geometry"]
    assert table["source"] == "worn.csv" and table["y_mm"][0] == -12.0 and len(table["sha256"]) == 64
    # λe at 3 mm: 0.025 plus the 2 mm jump at ≈ 2.55 mm, 2h·sqrt(1 − (a/ŷ)²)/(πŷ) (tests/test_sim_profiles.py)
    assert doc["equivalent_conicity"] == pytest.approx(0.025 + 4 * np.sqrt(1 - (2.55 / 3) ** 2) / (3 * np.pi), rel=0.03)
    with db.session() as s:
        conf = repo.get_configuration(s, "p", "worn")
        assert conf.parameters["contact_geometry"]["delta_r_mm"] == table["delta_r_mm"]
        base = repo.load_signalsets(s, "p", "baseline")
        worn = repo.load_signalsets(s, "p", "worn")
    sid = sorted(base)[0]
    assert not np.allclose(base[sid].channels["ay_cb_b1"], worn[sid].channels["ay_cb_b1"])
    # the diagnosis of the configuration with the table: no conicity candidate, said why
    res = diagnose(db, "p", "worn", effects=["conicity"], include_parameters=False, measurement=False,
                   workers=1, n_boot=20).to_dict()
    skipped = {x["name"]: x["reason"] for x in res["skipped"]}
    assert "conicity" in skipped and "measured profiles" in skipped["conicity"] and "'worn.csv'" in skipped["conicity"]
    assert [c["name"] for c in res["candidates"]] == []


def test_profile_skipped_only_with_a_table():
    assert profile_skipped({}, None) == []
    assert profile_skipped({"contact_geometry": {"y_mm": [0, 1, 2], "delta_r_mm": [0, 1, 2]}}, ["friction_damping"]) == []
    out = profile_skipped({"model.contact_geometry": {"source": "a.csv"}}, None)
    assert [x["name"] for x in out] == ["conicity"] and "'a.csv'" in out[0]["reason"]

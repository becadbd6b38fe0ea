"""Bad campaign folders: a precise CampaignFormatError and an unchanged database.

Each case starts from a valid small campaign ("bad", 2 sections, CSV), breaks one thing,
and checks the error names the file and field, and that row counts and every stored
signal hash of the campaign already in the database ("good") are unchanged.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from railval.core.errors import CampaignFormatError
from railval.db import repo
from railval.db.engine import connect
from railval.db.importer import import_campaign, validate_campaign_folder, write_validated
from railval.db.io import read_table, write_table
from tests.factories import write_demo_campaign


@pytest.fixture(scope="module")
def template(tmp_path_factory):
    folder = tmp_path_factory.mktemp("template")
    write_demo_campaign(folder, n_sections=2, fmt="csv", seed=5, name="bad")
    return folder


@pytest.fixture(scope="module")
def good_db(module_db_url, tmp_path_factory):
    folder = tmp_path_factory.mktemp("good")
    write_demo_campaign(folder, n_sections=1, fmt="parquet", seed=6, name="good")
    database = connect(module_db_url)
    database.init()
    import_campaign(database, folder)
    yield database
    database.dispose()


def _snapshot(database):
    with database.session() as s:
        return repo.row_counts(s), repo.signal_hashes(s, "good"), repo.signal_hashes(s, "good", "baseline")


@pytest.fixture
def folder(template, tmp_path):
    target = tmp_path / "campaign"
    shutil.copytree(template, target)
    return target


def _manifest(folder):
    return json.loads((folder / "campaign.json").read_text())


def _save(folder, manifest):
    (folder / "campaign.json").write_text(json.dumps(manifest))


def _edit_table(path, fn):
    cols = read_table(path)
    fn(cols)
    write_table(path, cols)


def _expect(database, folder, file, field, match):
    before = _snapshot(database)
    with pytest.raises(CampaignFormatError, match=match) as info:
        import_campaign(database, folder)
    assert info.value.file == file
    assert info.value.field == field
    assert _snapshot(database) == before
    with database.session() as s:
        assert [c.name for c in repo.list_campaigns(s)] == ["good"]
    return info.value


def test_valid_template_imports(good_db, folder):
    vc = validate_campaign_folder(folder)
    assert vc.name == "bad" and len(vc.recordings) == 4
    # (validation alone writes nothing)
    assert _snapshot(good_db)[0]["campaign"] == 1


def test_malformed_json(good_db, folder):
    (folder / "campaign.json").write_text('{"format": {"id": "railval-campaign",')
    err = _expect(good_db, folder, "campaign.json", None, "malformed JSON at line 1")
    assert "column" in str(err)


def test_missing_data_file(good_db, folder):
    (folder / "measured" / "S02.csv").unlink()
    _expect(good_db, folder, "measured/S02.csv", "sections[1].measured", "does not exist")


def test_truncated_csv(good_db, folder):
    path = folder / "sim" / "baseline" / "S02.csv"
    text = path.read_bytes()
    path.write_bytes(text[: len(text) // 2])  # cut inside a row
    _expect(good_db, folder, str(path), None, "cannot read .csv file")


def test_unreadable_parquet(good_db, folder):
    cols = read_table(folder / "measured" / "S01.csv")
    write_table(folder / "measured" / "S01.parquet", cols)
    data = (folder / "measured" / "S01.parquet").read_bytes()
    (folder / "measured" / "S01.parquet").write_bytes(data[: len(data) // 3])
    m = _manifest(folder)
    m["sections"][0]["measured"] = "measured/S01.parquet"
    _save(folder, m)
    _expect(good_db, folder, str(folder / "measured" / "S01.parquet"), None,
            "cannot read .parquet file")


def test_unknown_channel_column(good_db, folder):
    def rename(cols):
        cols["Y_w5L"] = cols.pop("Y_w1L")
    _edit_table(folder / "measured" / "S01.csv", rename)
    _expect(good_db, folder, "measured/S01.csv", "Y_w5L", "unknown channel column 'Y_w5L'")


def test_simulation_channel_missing_from_measurement(good_db, folder):
    _edit_table(folder / "measured" / "S01.csv", lambda c: c.pop("az_cb_b2"))
    _expect(good_db, folder, "sim/baseline/S01.csv", "az_cb_b2",
            "'az_cb_b2' is not in the measurement of section 'S01'")


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
def test_non_finite_values(good_db, folder, value):
    def spoil(cols):
        cols["Q_w2R"][123] = value
    _edit_table(folder / "sim" / "baseline" / "S01.csv", spoil)
    _expect(good_db, folder, "sim/baseline/S01.csv", "Q_w2R", f"holds {value} at sample 123")


def test_non_monotonic_time(good_db, folder):
    def spoil(cols):
        cols["time_s"][50], cols["time_s"][51] = cols["time_s"][51], cols["time_s"][50]
    _edit_table(folder / "measured" / "S02.csv", spoil)
    _expect(good_db, folder, "measured/S02.csv", "time_s", "not strictly increasing at sample 51")


def test_non_monotonic_distance(good_db, folder):
    def spoil(cols):
        cols["distance_m"][400] = cols["distance_m"][399] - 0.01
    _edit_table(folder / "measured" / "S01.csv", spoil)
    _expect(good_db, folder, "measured/S01.csv", "distance_m",
            "distance_m is not strictly increasing at sample 400")


def test_mismatched_column_lengths(good_db, folder):
    import h5py

    cols = read_table(folder / "measured" / "S01.csv")
    with h5py.File(folder / "measured" / "S01.h5", "w") as fh:
        for k, v in cols.items():
            fh.create_dataset(k, data=v[:-7] if k == "ay_cb_b1" else v)
    m = _manifest(folder)
    m["sections"][0]["measured"] = "measured/S01.h5"
    _save(folder, m)
    n = cols["time_s"].shape[0]
    _expect(good_db, folder, "measured/S01.h5", "ay_cb_b1",
            f"column 'ay_cb_b1' has {n - 7} samples, time_s has {n}")


def test_inconsistent_sampling(good_db, folder):
    def drop_one(cols):
        for k in cols:
            cols[k] = np.delete(cols[k], 1000)  # a lost sample: a 2-period gap in time_s
    _edit_table(folder / "measured" / "S02.csv", drop_one)
    _expect(good_db, folder, "measured/S02.csv", "time_s", "not equally spaced")


def test_empty_signal(good_db, folder):
    path = folder / "measured" / "S01.csv"
    path.write_text(path.read_text().splitlines()[0] + "\n")  # header only
    _expect(good_db, folder, str(path), "time_s", "header but no samples")


def test_empty_signal_binary_format(good_db, folder):
    cols = read_table(folder / "measured" / "S01.csv")
    write_table(folder / "measured" / "S01.parquet", {k: v[:0] for k, v in cols.items()})
    m = _manifest(folder)
    m["sections"][0]["measured"] = "measured/S01.parquet"
    _save(folder, m)
    _expect(good_db, folder, "measured/S01.parquet", "time_s", "column 'time_s' is empty")


def _set(path, value):
    """A manifest edit: set the value at ``path`` (keys and indices)."""
    def edit(m):
        target = m
        for key in path[:-1]:
            target = target[key]
        target[path[-1]] = value
    return edit


def _delete(path):
    def edit(m):
        target = m
        for key in path[:-1]:
            target = target[key]
        del target[path[-1]]
    return edit


def _cycle(m):
    m["configurations"].append(dict(m["configurations"][0], name="b", parent="baseline"))
    m["configurations"][0]["parent"] = "b"


#: (case id, manifest edit, file named by the error, field named, message pattern)
MANIFEST_CASES = [
    ("schema_violation", _set(["vehicle", "kind"], "tram"), "campaign.json", "vehicle.kind",
     "schema violation: 'tram'"),
    ("schema_missing_key", _delete(["sections", 1, "speed_kmh"]), "campaign.json", "sections[1]",
     "'speed_kmh' is a required property"),
    ("path_outside_folder", _set(["sections", 0, "measured"], "../elsewhere.csv"),
     "campaign.json", "sections[0].measured", "outside the campaign folder"),
    ("unknown_unit", _set(["channels", 0, "unit"], "lbf"), "campaign.json", "channels[0].unit",
     "unknown unit 'lbf' for kind 'Y'"),
    ("duplicate_section_ids", _set(["sections", 1, "id"], "S01"), "campaign.json",
     "sections[1].id", "duplicate section id 'S01'"),
    ("unknown_parent", _set(["configurations", 0, "parent"], "ghost"), "campaign.json",
     "configurations[0].parent", "unknown parent configuration 'ghost'"),
    ("parent_cycle", _cycle, "campaign.json", "configurations[0].parent", "cycle"),
    ("duplicate_campaign_name", _set(["name"], "good"), "campaign.json", "name",
     "campaign named 'good' already exists"),
    ("evaluated_outside_data", _set(["sections", 0, "evaluated", "end_m"], 1e6),
     "measured/S01.csv", "distance_m", "not inside the recorded distance"),
    ("radius_below_zones", _set(["sections", 0, "radius_m"], 180), "campaign.json",
     "sections[0].radius_m", "below 250 m"),
    ("channel_name_vs_position", _set(["channels", 0, "position"], "w2L"), "campaign.json",
     "channels[0].name", "must be kind_position"),
]


@pytest.mark.parametrize("edit,file,field,match", [c[1:] for c in MANIFEST_CASES],
                         ids=[c[0] for c in MANIFEST_CASES])
def test_manifest_errors(good_db, folder, edit, file, field, match):
    m = _manifest(folder)
    edit(m)
    _save(folder, m)
    _expect(good_db, folder, file, field, match)


def test_failure_while_writing_rolls_back_everything(good_db, folder):
    vc = validate_campaign_folder(folder)
    blob, sha, prov = next(iter(vc.recordings[-1].signals.values()))
    vc.recordings[-1].signals["not_a_channel"] = (blob, sha, prov)  # fails after the flush
    before = _snapshot(good_db)
    with pytest.raises(KeyError), good_db.session() as s:
        write_validated(s, vc)
    assert _snapshot(good_db) == before

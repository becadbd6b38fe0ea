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
    # a vehicle naming a built-in template carries that template's parameters only ...
    ("vehicle_parameter_unknown_to_template",
     _set(["vehicle", "parameters", "bogie_centres_m"], 19.0), "campaign.json",
     "vehicle.parameters.bogie_centres_m",
     "'bogie_centres_m' is not a parameter of vehicle template 'coach'"),
    # ... inside its bounds
    ("vehicle_parameter_out_of_bounds", _set(["vehicle", "parameters", "m_carbody"], -5.0),
     "campaign.json", "vehicle.parameters", "'m_carbody' = -5.0 kg is outside its bounds"),
]


@pytest.mark.parametrize("edit,file,field,match", [c[1:] for c in MANIFEST_CASES],
                         ids=[c[0] for c in MANIFEST_CASES])
def test_manifest_errors(good_db, folder, edit, file, field, match):
    m = _manifest(folder)
    edit(m)
    _save(folder, m)
    _expect(good_db, folder, file, field, match)


def test_vehicle_of_an_external_template_keeps_its_own_parameters(sqlite_database, folder):
    """Another template name is an external model's: its parameters are kept as given."""
    m = _manifest(folder)
    m["vehicle"]["template"] = "mbs-coach-v3"
    m["vehicle"]["parameters"] = {"bogie_pivot_distance_m": 19.0}
    m["name"] = "external"
    _save(folder, m)
    import_campaign(sqlite_database, folder)
    with sqlite_database.session() as s:
        vehicle = repo.get_campaign(s, "external").vehicle
        assert (vehicle.template, vehicle.parameters) == ("mbs-coach-v3", {"bogie_pivot_distance_m": 19.0})


def test_failure_while_writing_rolls_back_everything(good_db, folder):
    vc = validate_campaign_folder(folder)
    blob, sha, prov = next(iter(vc.recordings[-1].signals.values()))
    vc.recordings[-1].signals["not_a_channel"] = (blob, sha, prov)  # fails after the flush
    before = _snapshot(good_db)
    with pytest.raises(KeyError), good_db.session(write=True) as s:
        write_validated(s, vc)
    assert _snapshot(good_db) == before


# -- hostile or clumsy manifests (parser limits, names, units, layout) -------------------
def _save_text(folder, manifest, placeholder, literal):
    """Write the manifest with the JSON string ``placeholder`` replaced by raw ``literal``."""
    text = json.dumps(manifest, indent=1)
    assert json.dumps(placeholder) in text
    (folder / "campaign.json").write_text(text.replace(json.dumps(placeholder), literal, 1))


@pytest.mark.parametrize("literal,match", [
    ("NaN", r"NaN at line \d+, column \d+ is not a number JSON allows"),
    ("Infinity", "Infinity at line .* is not a number JSON allows"),
    ("-Infinity", "-Infinity at line .* is not a number JSON allows"),
    ("1e400", "number 1e400 at line .* is beyond the float range"),
    ("9" * 5000, "number of 5000 characters at line .* NUMBER_MAX_CHARS = 40"),
])
def test_number_literals_refused(good_db, folder, literal, match):
    m = _manifest(folder)
    m["sections"][0]["radius_m"] = "@@"
    _save_text(folder, m, "@@", literal)
    _expect(good_db, folder, "campaign.json", None, match)


def test_deep_nesting_refused(good_db, folder):
    m = _manifest(folder)
    m["vehicle"]["parameters"] = {"deep": "@@"}
    _save_text(folder, m, "@@", "[" * 100_000 + "]" * 100_000)
    _expect(good_db, folder, "campaign.json", None, "nesting deeper than 64 levels at line")


def test_duplicate_json_key_refused(good_db, folder):
    m = _manifest(folder)
    m["vehicle"]["Q0_kN"] = "@@"
    _save_text(folder, m, "@@", '77.3, "Q0_kN": 7.73')
    _expect(good_db, folder, "campaign.json", None, "duplicate key 'Q0_kN' in one JSON object")


@pytest.mark.parametrize("path,value,field,match", [
    (["name"], "bad\x00name", "name", "NUL character"),
    (["description"], "text\x00", "description", "NUL character"),
    (["configurations", 0, "name"], "base\tline", "configurations[0].name",
     r"holds the character '\\t' \(U\+0009\)"),
    (["name"], '"><img src=x onerror=alert(1)>', "name", "holds the character '\"'"),
    (["configurations", 0, "name"], "<script>", "configurations[0].name",
     "holds the character '<'"),
    (["name"], "x" * 201, "name", "201 characters is longer than the limit 200"),
    (["sections", 0, "id"], "S" * 101, "sections[0].id",
     "101 characters is longer than the limit 100"),
    (["vehicle", "name"], "v" * 201, "vehicle.name", "longer than the limit 200"),
    (["sections", 0, "country"], "D\x07E", "sections[0].country", r"control character U\+0007"),
])
def test_names_and_text_refused(good_db, folder, path, value, field, match):
    m = _manifest(folder)
    _set(path, value)(m)
    _save(folder, m)
    _expect(good_db, folder, "campaign.json", field, match)


def test_evaluated_range_on_transitions_refused(good_db, folder):
    m = _manifest(folder)
    sec = m["sections"][1]
    lay = sec["layout"]
    assert sec["radius_m"] > 0 and lay["transition_in_m"] > 10
    start = lay["straight_in_m"]
    sec["evaluated"] = {"start_m": start, "end_m": start + lay["transition_in_m"]}
    _save(folder, m)
    _expect(good_db, folder, "campaign.json", "sections[1].evaluated",
            "lies on the transitions or straights of the layout: only 0 m")


def _declare_unit(folder, kind_prefix, unit, check=None):
    m = _manifest(folder)
    for ch in m["channels"]:
        if ch["name"].startswith(kind_prefix):
            ch["unit"] = unit
            if check is not None:
                ch["check_unit"] = check
    _save(folder, m)


def test_unit_newton_on_kilonewton_data_refused(good_db, folder):
    _declare_unit(folder, "Q_", "N")
    _expect(good_db, folder, "measured/S01.csv", "Q_w1L",
            "mean vertical wheel force Q of channel 'Q_w1L' is 0.07.* kN .*unit declared N.* "
            "look like kN declared as N")


def test_guiding_force_kilonewton_data_declared_newton_refused(good_db, folder):
    """Y declared in N holding kN values would be stored ×0.001 (too small for their unit)."""
    _declare_unit(folder, "Y_", "N")
    _expect(good_db, folder, "measured/S01.csv", "Y_w1L",
            r"99 % of \|Y\| of channel 'Y_w1L' stay below .* kN .*unit declared N.*too small"
            ".*look like kN declared as N")


def _declare_channel(folder, name, unit, scale=1.0):
    """Declare the one channel ``name`` in ``unit`` and multiply its samples in every data
    file by ``scale`` (1000: kN values rewritten as the N values they are)."""
    m = _manifest(folder)
    [ch] = [ch for ch in m["channels"] if ch["name"] == name]
    ch["unit"] = unit
    _save(folder, m)
    if scale != 1.0:
        for path in sorted(folder.rglob("S*.csv")):
            def rescale(cols):
                cols[name] = cols[name] * scale
            _edit_table(path, rescale)


def test_one_wheel_load_channel_in_newton_among_kilonewton_refused(good_db, folder):
    """One Q channel declared N holding kN values: the mean over the four Q channels stays
    within a factor 3 of Q0 (3 · 77 + 0.077) / 4 ≈ 58 kN, so only a per-channel check finds
    the channel that would be stored ×0.001."""
    _declare_channel(folder, "Q_w2R", "N")
    _expect(good_db, folder, "measured/S01.csv", "Q_w2R",
            "mean vertical wheel force Q of channel 'Q_w2R' is 0.0[67].* kN \\(unit declared N\\)"
            ".*look like kN declared as N")


def test_one_guiding_force_channel_in_newton_among_true_newton_refused(good_db, folder):
    """Y_w1L holds true N values (×1000) and Y_w2R kN values, both declared N: the largest
    99th percentile over the N channels reaches 0.005·Q0, only the channel itself does not."""
    _declare_channel(folder, "Y_w1L", "N", scale=1000.0)
    _declare_channel(folder, "Y_w2R", "N")
    _expect(good_db, folder, "measured/S01.csv", "Y_w2R",
            r"99 % of \|Y\| of channel 'Y_w2R' stay below .* kN \(unit declared N\)"
            ".*look like kN declared as N")


def test_newton_data_declared_kilonewton_refused(good_db, folder):
    """N values (×1000) in a channel declared kN would be stored 1000 times too large."""
    _declare_channel(folder, "Q_w1R", "kN", scale=1000.0)
    _expect(good_db, folder, "measured/S01.csv", "Q_w1R",
            r"mean vertical wheel force Q of channel 'Q_w1R' is 7\.\d+e\+04 kN \(unit declared kN\)"
            ".*look like N declared as kN")


def test_guiding_force_newton_data_declared_kilonewton_refused(good_db, folder):
    _declare_channel(folder, "Y_w2L", "kN", scale=1000.0)
    _expect(good_db, folder, "measured/S01.csv", "Y_w2L",
            r"99 % of \|Y\| of channel 'Y_w2L' reach .* kN \(unit declared kN\), more than any "
            r"wheel carries: at most 231 kN \(3·Q0\) expected — the data look like N declared as kN")


def test_one_true_newton_channel_imports_converted(good_db, folder):
    """A channel really in N among kN channels is accepted and stored ×0.001."""
    _declare_channel(folder, "Q_w1L", "N", scale=1000.0)
    raw = read_table(folder / "measured" / "S01.csv")["Q_w1L"]
    vc = validate_campaign_folder(folder)
    from railval.db import codec

    stored = codec.decode(vc.recordings[0].signals["Q_w1L"][0])
    assert np.array_equal(stored, raw * 1e-3)
    assert vc.recordings[0].signals["Q_w1L"][2]["unit_conversion"] == {
        "from": "N", "to": "kN", "factor": 1e-3}


def test_guiding_force_unit_check_override(good_db, folder):
    _declare_unit(folder, "Y_", "N", check=False)
    vc = validate_campaign_folder(folder)
    raw = read_table(folder / "measured" / "S01.csv")["Y_w1L"]
    from railval.db import codec

    assert np.allclose(codec.decode(vc.recordings[0].signals["Y_w1L"][0]), raw * 1e-3)


def test_unit_g_on_ms2_data_refused(good_db, folder):
    _declare_unit(folder, "ay_cb_", "g")
    _expect(good_db, folder, "measured/S01.csv", "ay_cb_b1",
            "unit declared g.*look like m/s² declared as g")


def test_unit_check_override_imports_as_declared(good_db, folder):
    _declare_unit(folder, "ay_cb_", "g", check=False)
    vc = validate_campaign_folder(folder)
    raw = read_table(folder / "measured" / "S01.csv")["ay_cb_b1"]
    from railval.db import codec

    stored = codec.decode(vc.recordings[0].signals["ay_cb_b1"][0])
    assert np.array_equal(stored, raw * 9.80665)


def test_value_beyond_float_range_after_conversion_refused(good_db, folder):
    _declare_unit(folder, "az_cb_", "g", check=False)

    def spoil(cols):
        cols["az_cb_b2"][77] = 1e308
    _edit_table(folder / "measured" / "S02.csv", spoil)
    _expect(good_db, folder, "measured/S02.csv", "az_cb_b2",
            "holds inf at sample 77 after conversion from g")


def test_huge_finite_value_refused(good_db, folder):
    def spoil(cols):
        cols["Y_w1R"][5] = 1e308
    _edit_table(folder / "sim" / "baseline" / "S01.csv", spoil)
    _expect(good_db, folder, "sim/baseline/S01.csv", "Y_w1R",
            r"holds 1e\+308 at sample 5 .*MAX_ABS_VALUE")


def test_boolean_csv_column_refused(good_db, folder):
    path = folder / "measured" / "S01.csv"
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    k = [h.strip('"') for h in header].index("Y_w2L")
    out = [lines[0]]
    for i, line in enumerate(lines[1:]):
        cells = line.split(",")
        cells[k] = "true" if i % 2 else "false"
        out.append(",".join(cells))
    path.write_text("\n".join(out) + "\n")
    _expect(good_db, folder, str(path), "Y_w2L", "column 'Y_w2L' is boolean")


def test_boolean_parquet_column_refused(good_db, folder):
    cols = read_table(folder / "measured" / "S01.csv")
    cols["Y_w2L"] = cols["Y_w2L"] > 0
    import pyarrow as pa
    import pyarrow.parquet as pq

    pq.write_table(pa.table(cols), folder / "measured" / "S01.parquet")
    m = _manifest(folder)
    m["sections"][0]["measured"] = "measured/S01.parquet"
    _save(folder, m)
    _expect(good_db, folder, "measured/S01.parquet", "Y_w2L", "holds booleans")


def test_semicolon_csv_named(good_db, folder):
    path = folder / "measured" / "S01.csv"
    path.write_text(path.read_text().replace(",", ";"))
    _expect(good_db, folder, str(path), "time_s", "separates columns with ';'")


def test_decimal_comma_csv_named(good_db, folder):
    path = folder / "measured" / "S01.csv"
    lines = path.read_text().splitlines()
    body = [ln.replace(",", ";").replace(".", ",").replace(";", ",") for ln in lines[1:]]
    path.write_text("\n".join([lines[0], *body]) + "\n")
    _expect(good_db, folder, str(path), None, "decimal comma")


def test_duplicate_parquet_column_named(good_db, folder):
    import pyarrow as pa
    import pyarrow.parquet as pq

    cols = read_table(folder / "measured" / "S01.csv")
    names = list(cols) + ["Y_w1L"]
    arrays = [pa.array(cols[n]) for n in names]
    pq.write_table(pa.Table.from_arrays(arrays, names=names), folder / "measured" / "S01.parquet")
    m = _manifest(folder)
    m["sections"][0]["measured"] = "measured/S01.parquet"
    _save(folder, m)
    err = _expect(good_db, folder, str(folder / "measured" / "S01.parquet"), "Y_w1L",
                  "column 'Y_w1L' appears twice")
    assert len(str(err).splitlines()) == 1


def test_hdf5_declaring_huge_dataset_refused_before_reading(good_db, folder):
    import time

    import h5py

    path = folder / "measured" / "S01.h5"
    cols = read_table(folder / "measured" / "S01.csv")
    with h5py.File(path, "w") as fh:
        for k, v in cols.items():
            fh.create_dataset(k, data=v)
        del fh["Y_w1L"]
        fh.create_dataset("Y_w1L", shape=(300_000_000,), dtype="f8", chunks=(100_000,),
                          compression="gzip", fillvalue=1.0)
    assert path.stat().st_size < 2_000_000
    m = _manifest(folder)
    m["sections"][0]["measured"] = "measured/S01.h5"
    _save(folder, m)
    t = time.perf_counter()
    _expect(good_db, folder, str(path), "Y_w1L",
            "declares 300000000 samples, more than the limit MAX_SAMPLES = 20000000")
    assert time.perf_counter() - t < 10


@pytest.mark.parametrize("ext", ["parquet", "mf4", "tdms", "mat"])
def test_declared_size_cap_other_formats(good_db, folder, ext, monkeypatch):
    from railval.db.io import formats

    cols = read_table(folder / "measured" / "S01.csv")
    write_table(folder / "measured" / f"S01.{ext}", cols)
    m = _manifest(folder)
    m["sections"][0]["measured"] = f"measured/S01.{ext}"
    _save(folder, m)
    monkeypatch.setattr(formats, "MAX_SAMPLES", 1000)
    before = _snapshot(good_db)
    with pytest.raises(CampaignFormatError,
                       match="declares .* samples, more than the limit MAX_SAMPLES = 1000") as info:
        import_campaign(good_db, folder)
    assert info.value.file == str(folder / "measured" / f"S01.{ext}")
    assert info.value.field in cols
    assert _snapshot(good_db) == before


def test_reversed_polarity_wheel_load_channel_imports(good_db, folder):
    """A Q transducer wired with reversed polarity reads −Q (mean ≈ −Q0): its unit is right,
    so the import keeps it as measured and the diagnosis names the fault (its sign
    candidate); only the magnitude of the mean is held against Q0."""
    _declare_channel(folder, "Q_w2R", "kN", scale=-1.0)
    raw = read_table(folder / "measured" / "S01.csv")["Q_w2R"]
    assert raw.mean() < 0
    vc = validate_campaign_folder(folder)
    from railval.db import codec

    stored = codec.decode(vc.recordings[0].signals["Q_w2R"][0])
    assert np.array_equal(stored, raw)

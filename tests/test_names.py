"""The safe set of names (core/names.py) and its use by the importer schema and the store."""

from __future__ import annotations

import json

import numpy as np
import pytest

from railval.core.errors import InvalidParameter, InvalidSignal
from railval.core.names import NAME_MAX_LENGTH, NAME_PATTERN, check_name, name_problem


@pytest.mark.parametrize("name", ["baseline", "baseline+friction_damping", "demo-coach",
                                  "variant 2 (k=1.5e6)", "Zürich #3", "a", "S01", "x" * 200])
def test_safe_names_accepted(name):
    assert check_name(name) == name


@pytest.mark.parametrize("name,why", [
    ('"><img src=x onerror=alert(1)>', "'\"'"),
    ("<script>alert(1)</script>", "'<'"),
    ("a&b", "'&'"),
    ("a'b", "\"'\""),
    ("a/b", "'/'"),
    ("nul\x00", r"U\+0000"),
    ("tab\there", r"U\+0009"),
    ("line\nbreak", r"U\+000A"),
    (" leading", "must start with a letter or digit"),
    ("trailing ", "must not end with a space"),
    ("", "must not be empty"),
    ("x" * (NAME_MAX_LENGTH + 1), "201 characters long, the limit is 200"),
])
def test_unsafe_names_refused_with_reason(name, why):
    with pytest.raises(InvalidParameter, match=why):
        check_name(name, "configuration name")


def test_schema_uses_the_same_pattern():
    from railval.db.importer import SCHEMA_PATH

    schema = json.loads(SCHEMA_PATH.read_text())
    assert schema["$defs"]["name"]["pattern"] == NAME_PATTERN
    assert schema["$defs"]["name"]["maxLength"] == NAME_MAX_LENGTH
    assert name_problem("ok") is None


def test_store_configuration_refuses_unsafe_name(sqlite_database, tmp_path):
    from railval.db import repo
    from railval.db.importer import import_campaign

    from tests.factories import write_demo_campaign

    write_demo_campaign(tmp_path / "c", n_sections=1, fmt="parquet", seed=3, name="c")
    import_campaign(sqlite_database, tmp_path / "c")
    with sqlite_database.session(write=True) as s:
        sets = repo.load_signalsets(s, "c", "baseline")
        before = repo.row_counts(s)
        with pytest.raises(InvalidParameter, match="holds the character '<'"):
            repo.store_configuration(s, "c", "<img src=x onerror=alert(1)>", parent=None,
                                     effects={}, parameters={}, description="",
                                     signalsets=sets)
    with sqlite_database.session() as s:
        assert repo.row_counts(s) == before


def test_huge_samples_refused_by_processing():
    """1e308 is finite but overflows the filters: refused with the channel named (it used to
    produce inf statistics and crash the verdict later)."""
    from railval.core import en14363
    from railval.core.types import SectionInfo, SignalSet

    fs, n = 200.0, 4000
    t = np.arange(n) / fs
    ch = {"Y_w1L": np.zeros(n), "Q_w1L": np.full(n, 77.0), "ay_cb_b1": np.zeros(n)}
    ch["ay_cb_b1"][2000] = 1e308
    ss = SignalSet(fs=fs, time_s=t, distance_m=t * 20.0, channels=ch)
    sec = SectionInfo(id="S1", radius_m=300.0, cant_mm=0.0, speed_kmh=72.0, zone=4,
                      eval_start_m=100.0, eval_end_m=300.0)
    with pytest.raises(InvalidSignal, match=r"S1: channel ay_cb_b1 holds 1e\+308.*MAX_ABS_SAMPLE"):
        en14363.evaluate_section(ss, sec)

"""Stored analysis runs on SQLite and PostgreSQL: kept across sessions, found by their
inputs' hash, listed newest first, removed with their configuration."""

from __future__ import annotations

import hashlib

import pytest

from railval.db import runs
from railval.db.models import AnalysisRun, Campaign, Configuration


def _config(database):
    with database.session(write=True) as s:
        c = Campaign(name="c", manifest={})
        s.add(c)
        s.flush()
        cfg = Configuration(campaign_id=c.id, name="baseline", effects={}, parameters={})
        s.add(cfg)
        s.flush()
        return c.id, cfg.id


def test_inputs_digest_is_the_sha256_of_canonical_json():
    expected = hashlib.sha256(b'{"a":1,"b":[1,2]}').hexdigest()
    assert runs.inputs_digest({"b": [1, 2], "a": 1}) == expected
    assert runs.inputs_digest({"a": 1, "b": [1, 2]}) != runs.inputs_digest({"a": 1, "b": [2, 1]})
    with pytest.raises(ValueError):
        runs.inputs_digest({"x": float("nan")})


def test_runs_survive_sessions_and_match_by_inputs(database):
    cid, fid = _config(database)
    with database.session(write=True) as s:
        runs.store_run(s, campaign_id=cid, configuration_id=fid, kind="diagnosis",
                       inputs_sha256="a" * 64, settings={"n": 1}, result={"top": "x"}, seconds=3)
        runs.store_run(s, campaign_id=cid, configuration_id=fid, kind="diagnosis",
                       inputs_sha256="b" * 64, settings={"n": 2}, result={"top": "y"})
    with database.session() as s:  # a new session (another tab, a reload) sees both
        assert runs.latest_run(s, fid, "diagnosis").result == {"top": "y"}
        assert runs.latest_run(s, fid, "diagnosis", "a" * 64).result == {"top": "x"}
        assert runs.latest_run(s, fid, "diagnosis", "c" * 64) is None
        assert runs.latest_run(s, fid, "metrics") is None
        assert [r.settings["n"] for r in runs.list_runs(s, fid, "diagnosis")] == [2, 1]
        with pytest.raises(ValueError, match="run kind 'bogus'"):
            runs.latest_run(s, fid, "bogus")


def test_runs_go_with_their_configuration(database):
    cid, fid = _config(database)
    with database.session(write=True) as s:
        runs.store_run(s, campaign_id=cid, configuration_id=fid, kind="metrics",
                       inputs_sha256="a" * 64, settings={}, result={})
    with database.session(write=True) as s:
        s.delete(s.get(Configuration, fid))
    with database.session() as s:
        assert s.query(AnalysisRun).count() == 0

"""Concurrent writers: imports queue on SQLite instead of failing, and two imports of the same
name end with the same clean "already exists" message on SQLite and PostgreSQL."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time

import pytest

from railval.core.errors import CampaignFormatError
from railval.db import importer, repo
from railval.db.engine import connect

from tests.factories import write_demo_campaign


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    base = tmp_path_factory.mktemp("conc")
    out = {}
    for name, seed in (("alpha", 1), ("beta", 2)):
        write_demo_campaign(base / name, n_sections=1, fmt="parquet", seed=seed, name=name)
        out[name] = base / name
    same = base / "alpha-again"
    write_demo_campaign(same, n_sections=1, fmt="parquet", seed=3, name="alpha")
    out["alpha-again"] = same
    return out


def _overlapping_imports(url, first, second):
    """Import ``first`` holding its transaction open 1.5 s after writing, while ``second``
    starts importing in another connection; returns (error of first, error of second)."""
    real_write = importer.write_validated
    wrote = threading.Event()
    errors: dict[str, BaseException | None] = {"first": None, "second": None}

    def slow_write(session, vc):
        out = real_write(session, vc)
        if vc.folder == first:
            session.flush()
            wrote.set()
            time.sleep(1.5)
        return out

    def run(key, folder):
        database = connect(url)
        try:
            importer.import_campaign(database, folder)
        except BaseException as exc:  # noqa: BLE001 - reported to the test
            errors[key] = exc
        finally:
            database.dispose()

    importer.write_validated = slow_write
    try:
        a = threading.Thread(target=run, args=("first", first))
        a.start()
        assert wrote.wait(60)
        b = threading.Thread(target=run, args=("second", second))
        b.start()
        a.join(120)
        b.join(120)
    finally:
        importer.write_validated = real_write
    return errors["first"], errors["second"]


def test_two_imports_at_once_both_succeed_on_sqlite(tmp_path, folders):
    url = f"sqlite:///{tmp_path / 'c.db'}"
    connect(url).init()
    first, second = _overlapping_imports(url, folders["alpha"], folders["beta"])
    assert first is None
    assert second is None, f"second import failed: {second!r}"
    database = connect(url)
    with database.session() as s:
        assert [c.name for c in repo.list_campaigns(s)] == ["alpha", "beta"]
    database.dispose()


def test_two_imports_of_one_name_give_already_exists(db_url, folders):
    connect(db_url).init()
    first, second = _overlapping_imports(db_url, folders["alpha"], folders["alpha-again"])
    assert first is None
    assert isinstance(second, CampaignFormatError), repr(second)
    assert str(second) == ("file campaign.json, field name: a campaign named 'alpha' already "
                           "exists in the database")


def test_two_cli_imports_at_once(db_url, folders):
    """Two `railval import` processes started together: both succeed, no traceback."""
    env = {**os.environ, "RAILVAL_DB": db_url}
    subprocess.run([sys.executable, "-m", "railval.app", "init"], env=env, check=True,
                   capture_output=True)
    procs = [subprocess.Popen([sys.executable, "-m", "railval.app", "import",
                               str(folders[n]), "--no-progress"], env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for n in ("alpha", "beta")]
    results = [p.communicate(timeout=300) for p in procs]
    for p, (out, err) in zip(procs, results, strict=True):
        assert p.returncode == 0, err
        assert "Traceback" not in err
    database = connect(db_url)
    with database.session() as s:
        assert [c.name for c in repo.list_campaigns(s)] == ["alpha", "beta"]
    database.dispose()

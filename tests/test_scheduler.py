"""Batch work on an existing Dask scheduler (``--scheduler``; a real ``LocalCluster`` with two
worker processes): ``railval simulate`` stores signals identical to the local run, ``railval
validate`` gives the identical verdict document, DynoTRAIN-style many-configuration validation
equals the process pool's."""

from __future__ import annotations

import json

import pytest
from sqlalchemy import select

from railval.app.cli import main


@pytest.fixture(scope="module")
def cluster():
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as lc:
        yield lc.scheduler_address


@pytest.fixture(scope="module")
def demo_url(tmp_path_factory):
    """A synthetic campaign of the built-in simulator (railval synth; 12 sections)."""
    url = f"sqlite:///{tmp_path_factory.mktemp('sched') / 'd.db'}"
    assert main(["--db", url, "init"]) == 0
    assert main(["--db", url, "synth", "--name", "demo", "--sections", "12"]) == 0
    return url


def _hashes(url: str, config: str) -> list[tuple[str, str, str]]:
    from railval.db.engine import connect
    from railval.db.models import Channel, Configuration, Recording, Section, Signal

    db = connect(url)
    try:
        with db.session() as s:
            rows = s.execute(select(Section.section_id, Channel.name, Signal.sha256)
                             .join(Recording, Signal.recording_id == Recording.id)
                             .join(Section, Recording.section_id == Section.id)
                             .join(Configuration, Recording.configuration_id == Configuration.id)
                             .join(Channel, Signal.channel_id == Channel.id)
                             .where(Configuration.name == config)).all()
    finally:
        db.dispose()
    return sorted(tuple(r) for r in rows)


def test_simulate_and_validate_on_a_scheduler_equal_local(cluster, demo_url, capsys):
    args = ["--db", demo_url, "simulate", "demo", "--effect", "friction_damping", "--json"]
    capsys.readouterr()
    assert main([*args[:4], "--config", "local", *args[4:], "--workers", "1"]) == 0
    assert main([*args[:4], "--config", "dask", *args[4:], "--scheduler", cluster]) == 0
    capsys.readouterr()
    local, dask = _hashes(demo_url, "local"), _hashes(demo_url, "dask")
    assert local and [(a, b, h) for a, b, h in local] == [(a, b, h) for a, b, h in dask]

    docs = {}
    for mode, extra in (("local", []), ("dask", ["--scheduler", cluster])):
        assert main(["--db", demo_url, "validate", "demo", "--config", "dask", "--boot", "200",
                     "--order", "3", "--json", *extra]) == 0
        docs[mode] = json.loads(capsys.readouterr().out)
    assert docs["local"]["quantities"] == docs["dask"]["quantities"]
    assert docs["local"]["validated"] == docs["dask"]["validated"]


def test_many_configurations_on_a_scheduler_equal_the_process_pool(cluster, demo_url):
    from railval.app.services.validation import validate_configurations
    from railval.db.engine import connect
    from railval.db.models import ResultCache

    db = connect(demo_url)
    try:
        with db.session(write=True) as s:
            s.query(ResultCache).delete()
        pool = validate_configurations(db, "demo", n_boot=100, workers=2, chunk_sections=4)
        with db.session(write=True) as s:  # nothing cached: the cluster computes everything
            s.query(ResultCache).delete()
        dask = validate_configurations(db, "demo", n_boot=100, scheduler=cluster, chunk_sections=4)
    finally:
        db.dispose()
    assert set(pool) == set(dask) and len(pool) >= 2
    for name in pool:
        assert pool[name].to_dict() == dask[name].to_dict()

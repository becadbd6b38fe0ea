"""The production topology with a demo campaign, for the tests that drive it (real nginx, the
app processes, PostgreSQL): one set-up instead of a copy per test module."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from railval.app.bench.topology import Topology, nginx_binary
from railval.db import users
from tests.browser_support import require_browser
from tests.conftest import backend_url, require_program


@contextmanager
def demo_topology(work: Path, *, n_sections: int, accounts: Sequence[tuple[str, str, str]],
                  prepare: Callable[[Any], Any] | None = None, **topology: Any) -> Iterator[tuple[Topology, Any, Any]]:
    """A started :class:`Topology` on a fresh PostgreSQL schema holding the demo campaign of
    ``n_sections`` sections (one configuration) and the ``accounts`` (name, password, role);
    ``prepare(db)`` runs before the processes start and its value is yielded with the topology
    and the database. ``topology``: :class:`Topology` fields (``n_apps``, ``admin``, …). The
    processes stop, the database is closed and the secret key's path is forgotten on exit."""
    require_browser()
    require_program(nginx_binary(), "nginx missing (apt-get install nginx-light)")
    from railval.db.engine import connect
    from railval.db.importer import import_campaign
    from tests.factories import write_demo_campaign

    with backend_url("postgresql", work) as url:
        topo = Topology(url, work / "site", **topology)
        topo.workdir.mkdir()
        topo._secrets()
        os.environ["RAILVAL_SECRET_KEY_FILE"] = str(topo.workdir / "secrets" / "railval_secret_key")
        db = connect(url)
        try:
            db.init()
            folder = work / "demo"
            write_demo_campaign(folder, n_sections=n_sections, fs=50.0, n_configs=1)
            db.actor = "eng"
            import_campaign(db, folder)
            with db.session(actor="admin", write=True) as s:
                for name, password, role in accounts:
                    users.create_user(s, name, password=password, roles=[role])
            prepared = prepare(db) if prepare is not None else None
            topo.start()
            yield topo, db, prepared
        finally:
            topo.stop()
            db.dispose()
            os.environ.pop("RAILVAL_SECRET_KEY_FILE", None)

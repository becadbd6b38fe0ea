"""``GET /health`` of ``railval serve`` (app/health.py): 200 with the process and schema
revision when the database is reachable at the newest revision, 503 with the reason otherwise;
no sign-in needed, nothing secret in the answer."""

from __future__ import annotations

import json
import os
import urllib.error
import urllib.request

from sqlalchemy import text


def test_health_reports_the_process_and_refuses_an_old_schema(sqlite_database):
    from railval.app.main import served
    from railval.db import users

    with sqlite_database.session(write=True) as s:  # sign-in required everywhere else
        users.create_user(s, "adm", password="admin password 1", roles=["admin"])
    with served(sqlite_database) as url:
        base = url.rsplit("/app", 1)[0]
        with urllib.request.urlopen(f"{base}/health", timeout=30) as r:
            doc = json.loads(r.read())
            assert r.headers["Cache-Control"] == "no-store"
        assert doc == {"process": os.getpid(), "database": "sqlite", "status": "ok",
                       "revision": sqlite_database.head_revision()}
        with sqlite_database.engine.begin() as conn:
            conn.execute(text("UPDATE alembic_version SET version_num = '0005_x'"))
        try:
            urllib.request.urlopen(f"{base}/health", timeout=30)
            raise AssertionError("an old schema must answer 503")
        except urllib.error.HTTPError as exc:
            assert exc.code == 503
            bad = json.loads(exc.read())
        assert bad["status"] == "unavailable" and "schema revision 0005_x" in bad["reason"]
        assert sqlite_database.url not in json.dumps(bad)

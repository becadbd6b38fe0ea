"""Health endpoint and the admin-only guard of Panel's admin page (docs/app.md, "Team server").

``GET /health`` answers ``200 {"status": "ok", "process": PID, "revision": R, "database":
"postgresql"|"sqlite"}`` when this app process reaches its database at the newest schema
revision, else ``503`` with ``"status": "unavailable"`` and the reason — what a proxy, a
container orchestrator (compose ``healthcheck``) or systemd watchdog script polls. It needs
no sign-in and reveals no URL, user or secret.

Panel's admin page (``railval serve --admin``: sessions, memory, logs of this process) opens
for users holding the ``admin`` role only (:func:`admin_only`, installed as Panel's
``authorize_callback``); everyone else gets 403.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from typing import Any

from tornado.web import RequestHandler

from railval.app.security import database_message


class HealthHandler(RequestHandler):
    """``GET /health`` (module docstring)."""

    def initialize(self, database: Any) -> None:
        self.database = database

    def get(self) -> None:
        doc: dict[str, Any] = {"process": os.getpid(), "database": self.database.engine.dialect.name}
        try:
            current = self.database.current_revision()
            head = self.database.head_revision()
        except Exception as exc:  # noqa: BLE001 - any failure means "not healthy"
            doc |= {"status": "unavailable", "reason": database_message(exc)}
            self.set_status(503)
        else:
            ok = current == head
            doc |= {"status": "ok" if ok else "unavailable", "revision": current}
            if not ok:
                doc["reason"] = f"schema revision {current}, this railval needs {head}"
                self.set_status(503)
        self.set_header("Content-Type", "application/json")
        self.set_header("Cache-Control", "no-store")
        self.finish(json.dumps(doc))


def admin_only(principal_of: Callable[[], Any]):
    """Panel ``authorize_callback``: ``/admin`` only when ``principal_of()`` (the principal of
    the request's session cookie) holds the ``admin`` role."""

    def authorize(_user_info: Any, path: str) -> bool:
        if not path.rstrip("/").endswith("/admin"):
            return True
        principal = principal_of()
        return principal is not None and "admin" in principal.roles

    return authorize

"""Server settings from the environment, secrets from files (docs/security.md, "Team server").

Every setting ``NAME`` is read from ``$NAME``, else from the file named by ``$NAME_FILE``
(its text, surrounding white space removed) — the way container secrets
(``/run/secrets/…``), systemd credentials (``$CREDENTIALS_DIRECTORY/…``) and Kubernetes
secret volumes hand a secret to a process without putting it into an image, a command line
or the environment of every child process.

========================= =================================================================
``RAILVAL_DB``            database URL (``sqlite:///FILE`` or ``postgresql+psycopg://…``)
``RAILVAL_DB_PASSWORD``   PostgreSQL password, put into ``RAILVAL_DB`` when its URL has none
``RAILVAL_SECRET_KEY``    seal secret of signals and cached results (:mod:`.integrity`)
``RAILVAL_COOKIE_SECRET`` sign-in cookie secret, the same on every app process
``BOKEH_SECRET_KEY``      Bokeh session-id signing secret, the same on every app process
``RAILVAL_SCHEDULER``     Dask scheduler address for batch work (``tcp://host:8786``)
========================= =================================================================
"""

from __future__ import annotations

import os
from pathlib import Path

from railval.core.errors import RailvalError

#: setting → what it holds (the table above; docs/security.md lists the same names)
SETTINGS: dict[str, str] = {
    "RAILVAL_DB": "database URL",
    "RAILVAL_DB_PASSWORD": "PostgreSQL password (added to RAILVAL_DB when its URL has none)",
    "RAILVAL_SECRET_KEY": "seal secret of signals and cached results (≥ 32 characters)",
    "RAILVAL_COOKIE_SECRET": "sign-in cookie secret, identical on every app process",
    "BOKEH_SECRET_KEY": "Bokeh session-id secret, identical on every app process",
    "RAILVAL_SCHEDULER": "Dask scheduler address for batch work",
}


class SettingError(RailvalError):
    """A ``*_FILE`` setting names a file that cannot be read."""


def setting(name: str) -> str | None:
    """``$NAME``, else the text of the file ``$NAME_FILE``, else None."""
    value = os.environ.get(name)
    if value:
        return value
    path = os.environ.get(f"{name}_FILE")
    if not path:
        return None
    try:
        return Path(path).read_text(encoding="utf-8").strip()
    except OSError as exc:
        raise SettingError(f"{name}_FILE={path}: {exc.strerror}") from None


def setting_origin(name: str) -> str:
    """Where :func:`setting` takes ``name`` from (for start-up messages, never the value)."""
    if os.environ.get(name):
        return f"${name}"
    if os.environ.get(f"{name}_FILE"):
        return f"file ${name}_FILE={os.environ[f'{name}_FILE']}"
    return "unset"

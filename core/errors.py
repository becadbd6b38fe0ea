"""The railval exception tree: every exception class railval defines derives from
:class:`RailvalError` (``tests/test_error_tree.py`` walks the sources and fails for any that
does not). Core-level classes live here; database and application classes live in their
layer's module and derive from a class of this file. ``railval`` CLI exit codes
(``app/cli/__init__.py``): any :class:`RailvalError` → 2 with its message, any other
exception → 1.

::

    RailvalError(Exception)                              core/errors.py
    ├── InvalidSignal(RailvalError, ValueError)          a signal violates a precondition
    │   └── BlobError                 db/codec.py        a stored array fails to decode or verify
    ├── InvalidParameter(RailvalError, ValueError)       a parameter is unknown or out of bounds
    ├── CampaignFormatError(RailvalError, ValueError)    a campaign folder/manifest is invalid
    ├── NotFound(RailvalError, LookupError)              a campaign/configuration/section is absent
    ├── CalibrationDidNotConverge(RailvalError, RuntimeError)
    ├── PermissionDenied(RailvalError, PermissionError)  core/roles.py      roles do not grant it
    ├── _BudgetSpent                  core/calibration.py  the local polish used its budget
    │                                                      (caught inside the calibration)
    ├── IntegrityError                db/integrity.py    stored evidence fails its hash or seal
    │                                                    (the one class of that name; the
    │                                                    database's own unique violation is
    │                                                    ``sqlalchemy.exc.IntegrityError``,
    │                                                    imported as ``UniqueViolation``)
    ├── RecordingProblem              db/checks.py       a recording check failed (``field``)
    ├── DatabaseNotInitialised        db/engine.py       schema missing or older: ``railval init``
    ├── WriteInReadSession            db/engine.py       a write in a read session (the write
    │                                                    door: ``session(write=True)``)
    ├── SettingError                  db/settings.py     a ``*_FILE`` setting cannot be read
    ├── BackupError                   db/backup.py       a backup cannot be written or restored
    ├── InvitationRefused             db/users.py        invitation unknown, expired or used
    ├── WorkshopClosed                db/workshops.py    answers to a closed workshop are refused
    ├── StartupRefused                app/auth.py        ``railval serve`` must not start
    ├── SignoffRefused                app/services/signoff.py  password, role or independence
    ├── JobCancelled                  app/state/jobs.py  the user cancelled a background job
    └── ReportError                   app/pdf.py         the report could not be produced

Messages name the file or field, the bound and the offending value.
"""


class RailvalError(Exception):
    """Base class of every error railval raises on purpose."""


class InvalidSignal(RailvalError, ValueError):
    """A signal violates a precondition (NaN, non-monotonic axis, empty, wrong length)."""


class InvalidParameter(RailvalError, ValueError):
    """A parameter is unknown, of the wrong type or outside its bounds."""


class CampaignFormatError(RailvalError, ValueError):
    """A campaign folder, manifest or data file is invalid. ``where`` names file and field."""

    def __init__(self, message: str, *, file: str | None = None, field: str | None = None):
        self.file = file
        self.field = field
        where = ", ".join(p for p in (f"file {file}" if file else "", f"field {field}" if field else "") if p)
        super().__init__(f"{where}: {message}" if where else message)


class NotFound(RailvalError, LookupError):
    """A campaign, configuration, section or channel does not exist."""


class CalibrationDidNotConverge(RailvalError, RuntimeError):
    """An optimiser stopped without reaching its tolerance."""

"""The railval exception tree.

::

    RailvalError(Exception)
    ├── InvalidSignal(RailvalError, ValueError)      a signal violates a precondition
    ├── InvalidParameter(RailvalError, ValueError)   a parameter is unknown or out of bounds
    ├── CampaignFormatError(RailvalError, ValueError) a campaign folder/manifest is invalid
    ├── NotFound(RailvalError, LookupError)          a campaign/configuration/section is absent
    └── CalibrationDidNotConverge(RailvalError, RuntimeError)

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

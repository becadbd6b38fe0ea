"""The safe set of user-chosen names: campaigns, configurations and section ids.

A name is 1–200 characters (:data:`NAME_MAX_LENGTH`, the size of the database columns that
hold campaign and configuration names), starts with a letter or a digit, and otherwise holds
only letters and digits (ASCII and the Latin-1 letters such as ``ä``, ``é``, ``ß``), space and
``_ . + - = , : ( ) # @``. Everything else is refused — in particular ``< > " ' & ` / \\``,
control characters (NUL, tab, newline …) and a trailing space — so a name can never be read
as markup, a path or a shell word wherever it is shown or used (docs/database.md, "Names").

:func:`check_name` is the one validator: the campaign importer (through the JSON Schema
pattern :data:`NAME_PATTERN`), :func:`railval.db.repo.store_configuration` (every
configuration the CLI, the services or the web app store) and the CLI verbs that take a new
name call it.
"""

from __future__ import annotations

import re

from railval.core.errors import InvalidParameter

#: longest name accepted (campaign.name and configuration.name are VARCHAR(200))
NAME_MAX_LENGTH = 200
#: longest section id accepted (section.section_id is VARCHAR(100))
SECTION_ID_MAX_LENGTH = 100
_LETTER = "A-Za-z0-9\u00c0-\u00d6\u00d8-\u00f6\u00f8-\u00ff"
#: the safe set as a regular expression (Python ``re`` and JSON Schema ``pattern`` alike)
NAME_PATTERN = f"^[{_LETTER}]([{_LETTER} _.+=,:()#@-]*[{_LETTER}_.+=,:()#@-])?$"
_NAME_RE = re.compile(NAME_PATTERN)
#: the characters besides letters and digits, as shown in error messages
NAME_PUNCTUATION = "space _ . + - = , : ( ) # @"


def name_problem(value: object, *, max_length: int = NAME_MAX_LENGTH) -> str | None:
    """Why ``value`` is not a safe name, or ``None`` when it is one."""
    if not isinstance(value, str):
        return f"must be text, got {type(value).__name__}"
    if not value:
        return "must not be empty"
    if len(value) > max_length:
        return f"is {len(value)} characters long, the limit is {max_length}"
    if _NAME_RE.fullmatch(value):
        return None
    bad = next((ch for ch in value if not _NAME_RE.fullmatch("a" + ch + "a")), None)
    if bad is not None:
        return (f"holds the character {bad!r} (U+{ord(bad):04X}); allowed are letters, digits "
                f"and {NAME_PUNCTUATION}")
    return "must start with a letter or digit and must not end with a space"


def check_name(value: object, what: str = "name", *, max_length: int = NAME_MAX_LENGTH) -> str:
    """Return ``value`` if it is a safe name, else raise :class:`InvalidParameter`.

    ``what`` names the thing in the message, e.g. ``"configuration name"`` or ``"--as"``.
    """
    problem = name_problem(value, max_length=max_length)
    if problem is not None:
        raise InvalidParameter(f"{what} {value!r} {problem}")
    return value  # type: ignore[return-value]

"""The project's PEP 517 build backend: setuptools' own hooks, unchanged, except that an
editable install does not print setuptools' two generic notices about editable installs.

Why: the repository's top-level folders ``core/``, ``db/`` and ``app/`` install as
``railval.core``, ``railval.db`` and ``railval.app`` (package-dir mapping in pyproject.toml),
so setuptools implements ``pip install -e .`` with a meta path finder and, on every editable
install, says "Please be careful with folders in your working directory with the same name as
your package" and that package-data options "may have no effect". Neither applies here: no
folder named ``railval`` exists in the repository (``tests/test_install.py`` keeps it so), and
the finder maps each package to its source folder, so its JSON schemas, migrations and styles
are read from there (the same test imports them through an editable install). Every other
warning — a deprecated configuration key, a missing file — still reaches the user.
"""

from __future__ import annotations

import logging
import warnings

from setuptools import build_meta as _setuptools
from setuptools.build_meta import *  # noqa: F401,F403 - every other hook as setuptools has it
from setuptools.warnings import InformationOnly

_STRATEGY_LOGGER = "setuptools.command.editable_wheel"


class _DropStrategyNotice(logging.Filter):
    """Drop only the "Editable install will be performed using …" strategy notice."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not str(record.msg).lstrip().startswith("Editable install will be performed")


def build_editable(wheel_directory, config_settings=None, metadata_directory=None):
    logger = logging.getLogger(_STRATEGY_LOGGER)
    notice = _DropStrategyNotice()
    logger.addFilter(notice)
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=r"\s*Editable installation",
                                    category=InformationOnly)
            return _setuptools.build_editable(wheel_directory, config_settings, metadata_directory)
    finally:
        logger.removeFilter(notice)

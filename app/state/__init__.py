"""UI state of the engineers' web app, apart from any view (docs/design.md §2).

Nothing here imports Panel, nor the database: every class is a :class:`param.Parameterized`
that a test can drive without a browser, and stored data arrives through ``app/services``
(``tests/test_architecture.py`` holds both). Pages (``app/pages/*.py``) are thin views bound
to these states; what a validation shows comes from the view model :mod:`railval.app.views`.
One module per page:

::

    backend     Backend: one unit of work per call through app.services
    app         AppState (campaign, configuration, section, channel, page, status area);
                run_job hands background work to the session's JobRunner
    jobs        JobRunner: background work with progress, server-wide job slots, reserved names
    compare     CompareState → CompareData (arrays + axis labels + evaluated range)
    dashboard   DashboardState: validation, drill-down rows; open_row() jumps to Compare
    metrics     MetricsState: metric tables (raw and synchronised)
    diagnose    DiagnoseState: ranked candidates, calibrate/re-simulate, lineage of the error
    report      ReportState: HTML/PDF of a configuration's validation
"""

from railval.app.scales import nice_limits, nice_step, nice_ticks, unit_label
from railval.app.state.app import PAGE_TITLES, PAGES, AppState
from railval.app.state.backend import Backend, CampaignOverview, ConfigInfo
from railval.app.state.compare import MEASURED, CompareData, CompareState, Trace
from railval.app.state.dashboard import DashboardState
from railval.app.state.diagnose import DiagnoseState
from railval.app.state.metrics import MetricsState
from railval.app.state.report import ReportState
from railval.core.diagnosis import PatternGrid, pattern_grids, where_grid

__all__ = [
    "MEASURED",
    "PAGES",
    "PAGE_TITLES",
    "AppState",
    "Backend",
    "CampaignOverview",
    "CompareData",
    "CompareState",
    "ConfigInfo",
    "DashboardState",
    "DiagnoseState",
    "MetricsState",
    "PatternGrid",
    "ReportState",
    "Trace",
    "nice_limits",
    "nice_step",
    "nice_ticks",
    "pattern_grids",
    "unit_label",
    "where_grid",
]

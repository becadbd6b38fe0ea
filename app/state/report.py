"""State of the Report page: HTML/PDF of a configuration's validation."""

from __future__ import annotations

import param

from railval.app.report import build_report
from railval.app.state.app import AppState


class ReportState(param.Parameterized):
    fmt = param.Selector(default="html", objects=["html", "pdf"])
    worst_cases = param.Integer(default=3, bounds=(0, 12))

    def __init__(self, app: AppState, **params):
        super().__init__(**params)
        self.app = app

    def build(self):
        return build_report(self.app.backend, self.app.campaign, self.app.configuration,
                            worst_cases=self.worst_cases)

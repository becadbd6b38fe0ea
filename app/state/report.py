"""State of the Report page: HTML/PDF of a configuration's validation."""

from __future__ import annotations

import param

from railval.app.report import build_report
from railval.app.services.workshop_cards import card_choices, chosen_cards
from railval.app.state.app import AppState


class ReportState(param.Parameterized):
    fmt = param.Selector(default="html", objects=["html", "pdf"])
    worst_cases = param.Integer(default=3, bounds=(0, 12))
    #: workshop plot cards chosen into the report: labels of :meth:`card_choices`
    cards = param.List(default=[])

    def __init__(self, app: AppState, **params):
        super().__init__(**params)
        self.app = app

    def card_choices(self) -> dict[str, tuple[str, int]]:
        """The plot cards of this configuration's workshops a user with ``workshop.results``
        may choose (label → (workshop, plot id)); none for others."""
        if not self.app.allowed("workshop.results"):
            return {}
        return card_choices(self.app.backend.database, self.app.campaign, self.app.configuration)

    def build(self):
        cards = None
        if self.cards:
            choices = self.card_choices()
            cards = chosen_cards(self.app.backend.database, self.app.configuration,
                                 [choices[c] for c in self.cards if c in choices],
                                 actor=self.app.principal)
        return build_report(self.app.backend, self.app.campaign, self.app.configuration,
                            worst_cases=self.worst_cases, cards=cards)

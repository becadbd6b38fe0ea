"""State of the validation dashboard: the validation of the selected configuration, the
selected quantity → drill-down rows; :meth:`DashboardState.open_row` jumps to Compare."""

from __future__ import annotations

from typing import Any

import param

from railval.app.state.app import AppState
from railval.app.views import ValidationView, view_of
from railval.core.diagnosis import PatternGrid, where_grid
from railval.core.quantities import DERIVED_SIGNALS, QUANTITIES, channel_for


class DashboardState(param.Parameterized):
    quantity = param.Selector(default=None, objects=[], allow_None=True,
                              doc="quantity whose drill-down is shown")
    top_n = param.Integer(default=15, bounds=(5, 200))

    def __init__(self, app: AppState, **params):
        super().__init__(**params)
        self.app = app

    def result(self, config: str | None = None):
        config = config or self.app.configuration
        return self.app.backend.validation(self.app.campaign, config)

    def summary(self, config: str | None = None) -> ValidationView:
        """The view model of the configuration's validation (:mod:`railval.app.views`); the
        drill-down selector lists its quantities."""
        view = view_of(self.result(config))
        self.param.quantity.objects = [r["quantity"] for r in view.quantities]
        return view

    def drilldown(self, quantity: str | None = None, config: str | None = None) -> list[dict[str, Any]]:
        """Pairs of one quantity ranked by their contribution |D_v|/std limit (largest first).

        Each row: section, position, zone, M_v, S_v, D_v, norm (= D_v / std limit, core's
        ``D_norm``).
        """
        quantity = quantity or self.quantity
        if quantity is None:
            return []
        return view_of(self.result(config)).drilldown(quantity, self.top_n)

    def where(self, config: str | None = None) -> PatternGrid:
        """Where the configuration fails: mean of D_v / std limit over the sections and
        positions of each quantity × EN zone (``ValidationResult.pairs``), as a grid."""
        return where_grid(self.result(config).pairs)

    def open_row(self, row: dict[str, Any]) -> None:
        objs = self.app.param.channel.objects
        q = QUANTITIES[row["quantity"]]
        derived = f"{q.signal}_{row['position']}" if q.signal in DERIVED_SIGNALS else None
        # a Y/Q or ΣY row opens the derived signal it is about, other rows their raw channel
        channel = derived if derived in objs else channel_for(row["quantity"], row["position"], objs)
        self.app.open_compare(row["section"], channel)

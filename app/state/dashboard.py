"""State of the validation dashboard: the validation of the selected configuration, the
selected quantity → drill-down rows; :meth:`DashboardState.open_row` jumps to Compare."""

from __future__ import annotations

from typing import Any

import param

from railval.app.state.app import AppState
from railval.core.diagnosis import PatternGrid, where_grid
from railval.core.quantities import DERIVED_SIGNALS, QUANTITIES, channel_for


def quantity_rows(result: Any) -> list[dict[str, Any]]:
    d = result.to_dict() if hasattr(result, "to_dict") else dict(result)
    rows = d.get("quantities", d.get("results", []))
    if isinstance(rows, dict):
        rows = [dict(v, quantity=k) if "quantity" not in v else v for k, v in rows.items()]
    return list(rows)


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

    def summary(self, config: str | None = None) -> dict[str, Any]:
        """``{"validated", "coverage", "quantities": [rows]}`` of the validation contract."""
        res = self.result(config)
        d = res.to_dict() if hasattr(res, "to_dict") else dict(res)
        rows = quantity_rows(res)
        self.param.quantity.objects = [r["quantity"] for r in rows]
        return {"validated": bool(d.get("validated")), "coverage": d.get("coverage", {}),
                "quantities": rows, "raw": d}

    def drilldown(self, quantity: str | None = None, config: str | None = None) -> list[dict[str, Any]]:
        """Pairs of one quantity ranked by their contribution |D_v|/std limit (largest first).

        Each row: section, position, channel, zone, M_v, S_v, D_v, norm (= D_v / std limit).
        """
        quantity = quantity or self.quantity
        if quantity is None:
            return []
        res = self.result(config)
        rows = _pairs_of(res, quantity)
        limit = next((r.get("std_limit") for r in quantity_rows(res) if r["quantity"] == quantity), None)
        for r in rows:
            r["norm"] = (r["D_v"] / limit) if limit else float("nan")
        rows.sort(key=lambda r: -abs(r["D_v"]))
        return rows[: self.top_n]

    def where(self, config: str | None = None) -> PatternGrid:
        """Where the configuration fails: mean of D_v / std limit over the sections and
        positions of each quantity × EN zone (``ValidationResult.pairs``), as a grid."""
        return where_grid(self.result(config).pairs)

    def open_row(self, row: dict[str, Any]) -> None:
        objs = self.app.param.channel.objects
        q = QUANTITIES.get(row.get("quantity") or "")
        derived = f"{q.signal}_{row.get('position')}" if q is not None and q.signal in DERIVED_SIGNALS else None
        # a Y/Q or ΣY row opens the derived signal it is about, other rows their raw channel
        channel = derived if derived in objs else channel_for(row.get("quantity"), row.get("position"), objs)
        self.app.open_compare(row["section"], channel)


def _pairs_of(result: Any, quantity: str) -> list[dict[str, Any]]:
    """All pairs of one quantity from ``ValidationResult.pairs`` (a DataFrame with columns
    quantity, section, zone, position, M, S, D, D_norm — core.validation)."""
    pairs = result.pairs
    sub = pairs[pairs["quantity"] == quantity]
    return [{
        "quantity": quantity, "section": str(r.section), "position": str(r.position),
        "zone": int(r.zone), "M_v": float(r.M), "S_v": float(r.S), "D_v": float(r.D),
    } for r in sub.itertuples(index=False)]


def definition_rows(doc: dict[str, Any]) -> list[dict[str, Any]]:
    """Per quantity that another reading of the open definitions can change (percentile
    method, sliding-window grid and mean; docs/validation.md): verdict, whether some reading
    flips it, which, and the range of mean/limit and std/limit over the readings."""
    out = []
    for q in doc.get("quantities", []):
        alts = q.get("definition_alternatives") or []
        if not alts:
            continue
        means = [a["mean_norm"] for a in alts if a.get("mean_norm") is not None]
        stds = [a["std_norm"] for a in alts if a.get("std_norm") is not None]
        flips = [a for a in alts if a.get("flips")]
        out.append({
            "quantity": q["quantity"],
            "verdict": "pass" if q.get("pass") else "FAIL",
            "definition_sensitive": bool(q.get("definition_sensitive")),
            "readings": len(alts),
            "mean/limit": q.get("mean_norm"),
            "mean/limit other readings": (min(means), max(means)) if means else None,
            "std/limit other readings": (min(stds), max(stds)) if stds else None,
            "flipped by": "" if not flips else (
                f"{'passes' if flips[0]['pass'] else 'fails'} with "
                f"{flips[0].get('label', flips[0]['description'])}"
                + (f" (and {len(flips) - 1} more of {len(alts)} readings)" if len(flips) > 1 else "")),
        })
    return out


def supplementary_rows(doc: dict[str, Any]) -> list[dict[str, Any]]:
    """The supplementary results (bogie-frame and PSD-band quantities) of a validation
    document, one row each (core.supplementary); they never change the verdict."""
    return [dict(r) for r in (doc.get("supplementary") or {}).get("quantities", [])]

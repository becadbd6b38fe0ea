"""Documents that read a stored review workshop back: its status and plot list (the CLI's
``--json`` documents and the organiser page), the plot kinds, the review link
(docs/workshops.md). Building a workshop is :mod:`railval.app.services.workshops`."""

from __future__ import annotations

from typing import Any

from railval.core.workshop import PLOT_KIND_IDS, PLOT_KINDS
from railval.db import workshops as wsdb


def workshop_scaling(settings: dict[str, Any] | None) -> str:
    """The scaling a stored workshop was rendered with; workshops made before the choice
    existed kept one range per kind over the whole workshop."""
    return (settings or {}).get("scaling", "workshop")


def plots_document(session, name: str) -> dict[str, Any]:
    """The ``workshop plots NAME --json`` document."""

    w = wsdb.get_workshop(session, name)
    return {"workshop": w.name, "plots": [
        {"id": p.id, "kind": p.kind, "section": p.section, "configuration": p.configuration,
         "channel": p.channel, "deviation": p.deviation, "sg_c": p.sg_c, "scaling": p.scaling,
         "twin": p.twin_id, "image_sha256": p.image_sha256}
        for p in wsdb.plots(session, w)]}


def status_document(session, name: str) -> dict[str, Any]:

    w = wsdb.get_workshop(session, name)
    prog = wsdb.progress(session, w)
    return {"workshop": w.name, "campaign": w.campaign.name, "status": w.status,
            "blind": bool(w.blind), "plots": len(wsdb.plots(session, w)),
            "repeats": w.repeat_share, "scaling": workshop_scaling(w.settings), "reviewers": prog,
            "answers": sum(r["answered"] for r in prog)}


def review_link(base_url: str, token: str) -> str:
    return f"{base_url.rstrip('/')}/review/{token}"


def kind_labels() -> dict[str, str]:
    return {k: PLOT_KINDS[k].label for k in PLOT_KIND_IDS}


def describe_kinds() -> list[dict[str, Any]]:
    return [{"id": k.id, "label": k.label, "domain": k.domain, "positions": list(k.positions),
             "quantities": list(k.quantities), "table1": k.table1} for k in PLOT_KINDS.values()]


__all__ = ["describe_kinds", "kind_labels", "plots_document", "review_link", "status_document",
           "workshop_scaling"]

"""Campaign export: write a stored campaign back as a campaign folder.

The folder follows ``docs/campaign-format.md``: ``campaign.json`` plus
``measured/<section>.<ext>`` and ``sim/<configuration>/<section>.<ext>``. Signals are
written in their canonical units (kN, m/s²) and the manifest declares exactly those, so
importing the exported folder reproduces every signal's content hash; the time axis is
rebuilt as ``t0 + i/fs``.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from railval.core.errors import InvalidParameter
from railval.db import codec
from railval.db.campaigns import CampaignArg, get_campaign, list_configurations, vehicle_info
from railval.db.io import FORMAT_EXTENSIONS, write_table
from railval.db.models import Campaign, Channel, Configuration, Recording, Section, Signal

EXPORT_FORMATS = ("parquet", "csv", "h5", "mat", "mf4", "tdms")


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._") or "unnamed"


def export_campaign(session: Session, campaign: CampaignArg, folder: str | Path,
                    fmt: str = "parquet") -> Path:
    """Write ``campaign`` (a :class:`railval.db.repo.CampaignRef`, or its name or id) to
    ``folder`` (created; must be empty if it exists) in format ``fmt``.

    Returns the path of the written ``campaign.json``.
    """
    if fmt not in FORMAT_EXTENSIONS:
        raise InvalidParameter(f"export format {fmt!r} unknown; choose one of {EXPORT_FORMATS}")
    folder = Path(folder)
    if folder.exists() and any(folder.iterdir()):
        raise InvalidParameter(f"export folder {folder} exists and is not empty")
    folder.mkdir(parents=True, exist_ok=True)
    camp = get_campaign(session, campaign)
    chans = list(session.scalars(select(Channel).where(Channel.campaign_id == camp.id)
                                 .order_by(Channel.id)))
    sections = list(session.scalars(select(Section).where(Section.campaign_id == camp.id)
                                    .order_by(Section.id)))
    confs = list_configurations(session, camp)
    files = _write_recordings(session, camp, folder, FORMAT_EXTENSIONS[fmt], sections, chans, confs)
    conf_names = {c.id: c.name for c in confs}
    veh = vehicle_info(session, camp)
    veh_out = {k: veh[k] for k in ("name", "kind", "secondary_suspension", "Q0_kN", "template",
                                   "parameters")}
    manifest: dict[str, Any] = {
        "format": {"id": "railval-campaign", "version": 1},
        "name": camp.name,
        "description": camp.description,
        "zone1_min_radius_m": camp.zone1_min_radius_m,
        "vehicle": veh_out,
        "channels": [{"name": c.name, "kind": c.kind, "position": c.position, "unit": c.unit}
                     for c in chans],
        "sections": [
            {
                "id": s.section_id, "country": s.country, "radius_m": s.radius_m,
                "cant_mm": s.cant_mm, "speed_kmh": s.speed_kmh,
                "curve_direction": s.curve_direction, "zone": s.zone_override,
                "evaluated": {"start_m": s.eval_start_m, "end_m": s.eval_end_m},
                **({"layout": s.layout} if s.layout is not None else {}),
                "measured": files[None][s.section_id],
            }
            for s in sections if s.section_id in files[None]
        ],
        "configurations": [
            {
                "name": c.name,
                "parent": conf_names.get(c.parent_id) if c.parent_id is not None else None,
                "effects": c.effects, "parameters": c.parameters, "description": c.description,
                "files": files[c.id],
            }
            for c in _parents_first(confs) if files[c.id]
        ],
    }
    path = folder / "campaign.json"
    path.write_text(json.dumps(manifest, indent=2, allow_nan=False))
    return path


def _write_recordings(session: Session, camp: Campaign, folder: Path, ext: str, sections: list[Section],
                      chans: list[Channel], confs: list[Configuration]) -> dict[int | None, dict[str, str]]:
    """Write every recording of ``camp`` as one table file (``measured/<section><ext>``,
    ``sim/<configuration>/<section><ext>``: time, distance and every channel, decoded with
    their content hash checked); returns configuration id (``None``: the measurement) →
    section id → file path relative to ``folder``."""
    conf_names = {c.id: c.name for c in confs}
    conf_dirs: dict[str, str] = {}
    for c in confs:  # distinct folder names even if two names sanitise alike
        base = _safe(c.name)
        d, k = base, 1
        while d in conf_dirs.values():
            k += 1
            d = f"{base}-{k}"
        conf_dirs[c.name] = d
    files: dict[int | None, dict[str, str]] = {None: {}}
    files.update({c.id: {} for c in confs})
    sec_by_id = {s.id: s for s in sections}
    chan_by_id = {c.id: c.name for c in chans}
    recs = session.execute(
        select(Recording).join(Section, Recording.section_id == Section.id)
        .where(Section.campaign_id == camp.id).order_by(Recording.id)
    ).scalars()
    for rec in recs:
        sid = sec_by_id[rec.section_id].section_id
        if rec.configuration_id is None:
            rel = f"measured/{_safe(sid)}{ext}"
        else:
            rel = f"sim/{conf_dirs[conf_names[rec.configuration_id]]}/{_safe(sid)}{ext}"
        columns: dict[str, np.ndarray] = {
            "time_s": rec.t0 + np.arange(rec.n, dtype=np.float64) / rec.fs,
            "distance_m": codec.decode(rec.distance_blob, rec.distance_sha256),
        }
        sigs = session.execute(
            select(Signal.channel_id, Signal.blob, Signal.sha256)
            .where(Signal.recording_id == rec.id).order_by(Signal.channel_id)
        )
        for channel_id, blob, sha in sigs:
            columns[chan_by_id[channel_id]] = codec.decode(blob, sha)
        write_table(folder / rel, columns)
        files[rec.configuration_id][sid] = rel
    return files


def _parents_first(confs: list[Configuration]) -> list[Configuration]:
    by_id = {c.id: c for c in confs}
    out: list[Configuration] = []
    done: set[int] = set()

    def visit(c: Configuration) -> None:
        if c.id in done:
            return
        if c.parent_id in by_id:
            visit(by_id[c.parent_id])
        done.add(c.id)
        out.append(c)

    for c in confs:
        visit(c)
    return out

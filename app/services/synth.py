"""Write a synthetic campaign (:mod:`railval.core.sim.synth`) as a campaign folder (docs/campaign-format.md)
and import it; seed the demo campaign of an empty database.

Folder layout::

    campaign.json              manifest (sections carry layout + measured irregularities)
    measured/S01.parquet …     "measurements" (truth model + nuisances)
    sim/baseline/S01.parquet … the baseline configuration

The truth goes to ``reveal`` (a separate JSON file) only when asked.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from railval.core import lazy
from railval.core.errors import CampaignFormatError
from railval.core.sim.synth import SynthCampaign, build_campaign, parse_hidden
from railval.core.types import CHANNEL_KINDS, split_channel
from railval.core.workers import process_alive

#: deferred (railval.core.lazy): the importer, the table writer and the ORM models (about
#: 190 more modules) only for the synthetic campaign's import
write_table = lazy.function("railval.db.io", "write_table")
import_campaign = lazy.function("railval.db.importer", "import_campaign")
repo = lazy.module("railval.db.repo")
check_campaign_name = lazy.function("railval.db.campaigns", "check_campaign_name")

DEMO_NAME = "demo-coach"
DEMO_HIDDEN = ["parasitic_yaw_stiffness"]

Progress = Callable[[str, float, dict], None]


def _json_safe(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_json_safe(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def write_folder(sc: SynthCampaign, folder: str | Path, *, ext: str = "parquet") -> Path:
    """Write ``sc`` as a campaign folder; return the folder path."""

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    first = next(iter(sc.measured.values()))
    channels = [{"name": n, "kind": split_channel(n)[0], "position": split_channel(n)[1],
                 "unit": CHANNEL_KINDS[split_channel(n)[0]]} for n in first.channels]
    sections, files = [], {}
    for sec in sc.sections:
        sid = sec.track.id
        rec = sec.manifest_record()
        rec["measured"] = f"measured/{sid}.{ext}"
        ss = sc.measured[sid]
        write_table(folder / rec["measured"], {"time_s": ss.time_s, "distance_m": ss.distance_m, **ss.channels})
        bs = sc.baseline[sid]
        files[sid] = f"sim/baseline/{sid}.{ext}"
        write_table(folder / files[sid], {"time_s": bs.time_s, "distance_m": bs.distance_m, **bs.channels})
        sections.append(rec)
    manifest = {
        "format": {"id": "railval-campaign", "version": 1},
        "name": sc.name,
        "description": sc.description,
        "zone1_min_radius_m": 5000,
        "vehicle": sc.vehicle_record(),
        "channels": channels,
        "sections": sections,
        "configurations": [{"name": "baseline", "parent": None, "effects": sc.baseline_effects,
                            "parameters": {}, "description": "nominal model (template defaults)",
                            "files": files}],
    }
    (folder / "campaign.json").write_text(json.dumps(_json_safe(manifest), indent=1))
    return folder


#: prefix of synth's temporary campaign folders: ``railval-synth-<pid>-<random>``
TEMP_PREFIX = "railval-synth-"


def remove_stale_folders(base: str | Path | None = None) -> list[Path]:
    """Remove the temporary folders of synth runs whose process no longer exists (a run
    killed with SIGKILL cannot remove its own, ≈ 70 MB each); returns the removed paths.
    Called at the start of every synth run."""
    removed = []
    for path in Path(base or tempfile.gettempdir()).glob(f"{TEMP_PREFIX}*-*"):
        pid = path.name[len(TEMP_PREFIX):].split("-", 1)[0]
        if path.is_dir() and pid.isdigit() and int(pid) != os.getpid() and not process_alive(int(pid)):
            shutil.rmtree(path, ignore_errors=True)
            removed.append(path)
    return removed


def synth(database: Any, *, name: str = "synth", template: str = "coach", hidden: list[str] | None = None,
          seed: int = 1, n_sections: int = 12, out: str | Path | None = None, reveal: str | Path | None = None,
          progress: Progress | None = None) -> dict:
    """Build, write and import a synthetic campaign; return a summary (no truth in it).

    ``hidden``: CLI-style items (``EFFECT``, ``EFFECT=VALUE`` or ``EFFECT:k=v,...``); default
    ``friction_damping``. ``out``: keep the folder there (else a temporary folder). ``reveal``:
    write the truth as JSON to this file.
    """

    def rep(stage: str, frac: float, **info):
        if progress:
            progress(stage, frac, info)

    check_campaign_name(name)  # also no digits only: that reads as another campaign's id
    with database.session() as s:  # before minutes of simulation, not after
        if any(c.name == name for c in repo.list_campaigns(s)):
            raise CampaignFormatError(f"a campaign named {name!r} already exists in the "
                                      "database", field="name")
    hid = parse_hidden(hidden or ["friction_damping"], template)
    sc = build_campaign(name=name, template=template, hidden=hid, seed=seed, n_sections=n_sections,
                        progress=lambda d, t: rep("simulate", 0.85 * d / t, done=d, total=t))
    remove_stale_folders()
    with tempfile.TemporaryDirectory(prefix=f"{TEMP_PREFIX}{os.getpid()}-") as tmp:
        folder = Path(out) if out else Path(tmp) / name
        rep("write", 0.87)
        write_folder(sc, folder)
        rep("import", 0.92)
        imported = import_campaign(database, folder)
    if reveal:
        Path(reveal).write_text(json.dumps(_json_safe(sc.truth), indent=1))
    rep("done", 1.0)
    return {"campaign": imported, "sections": len(sc.sections), "template": template,
            "configurations": ["baseline"], "folder": str(out) if out else None,
            "reveal": str(reveal) if reveal else None}


def ensure_demo(database: Any, progress: Progress | None = None) -> str | None:
    """Seed the demo campaign (coach, hidden parasitic yaw stiffness: the model underestimates the
    guiding forces in tight curves) when the database holds no campaign. Returns its name, or
    ``None`` when the database already had campaigns. Takes a few seconds."""

    with database.session() as s:
        if repo.list_campaigns(s):
            return None
    return synth(database, name=DEMO_NAME, template="coach", hidden=DEMO_HIDDEN, seed=2026,
                 progress=progress)["campaign"]

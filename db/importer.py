"""Campaign import: check a whole campaign folder, then write it in one transaction.

``validate_campaign_folder(folder)`` reads and checks everything — the manifest against
``db/schema/campaign.schema.json``, the cross-references (channels, sections, parents),
units, and every data file (:func:`railval.db.checks.check_recording`) — and returns a
:class:`ValidatedCampaign` holding the already encoded signals. Nothing is written.
``import_campaign(database_or_session, folder)`` validates and then writes the campaign in
one transaction: a bad folder raises :class:`railval.core.errors.CampaignFormatError` (naming the
file and field) and leaves the database unchanged.

Units are converted to the canonical unit of each channel kind (``railval.core.types.CHANNEL_KINDS``)
on import and the conversion is recorded in each signal's provenance:
N → kN (× 0.001), g → m/s² (× 9.80665, the standard gravity of ISO 80000-3).
"""

from __future__ import annotations

import datetime as dt
import hashlib
import json
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy import insert, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from railval.core.errors import CampaignFormatError, InvalidParameter
from railval.core.types import BODY_POSITIONS, CHANNEL_KINDS, WHEEL_POSITIONS
from railval.core.zones import zone_for_radius
from railval.db import audit, codec
from railval.db.checks import RecordingProblem, check_recording
from railval.db.io import read_table
from railval.db.models import Campaign, Channel, Configuration, Recording, Section, Signal, Vehicle

SCHEMA_PATH = Path(__file__).with_name("schema") / "campaign.schema.json"
MANIFEST = "campaign.json"
STANDARD_GRAVITY = 9.80665  # m/s², ISO 80000-3 / CGPM 1901

#: unit accepted in a manifest → (canonical unit, factor to the canonical unit)
FORCE_UNITS = {"kN": ("kN", 1.0), "N": ("kN", 1e-3)}
ACC_UNITS = {"m/s^2": ("m/s^2", 1.0), "m/s2": ("m/s^2", 1.0), "m/s²": ("m/s^2", 1.0),
             "g": ("m/s^2", STANDARD_GRAVITY)}
UNITS_BY_KIND = {kind: FORCE_UNITS if unit == "kN" else ACC_UNITS
                 for kind, unit in CHANNEL_KINDS.items()}

Progress = Callable[[int, int, str], None]


@dataclass
class ValidatedRecording:
    """One checked data file, its signals already encoded (blob, sha256, provenance)."""

    section_id: str
    configuration: str | None
    file: str
    fs: float
    t0: float
    n: int
    distance_blob: bytes
    distance_sha256: str
    signals: dict[str, tuple[bytes, str, dict[str, Any]]] = field(default_factory=dict)


@dataclass
class ValidatedCampaign:
    """Everything needed to write a campaign; produced only when all checks passed."""

    folder: Path
    manifest: dict[str, Any]
    recordings: list[ValidatedRecording]
    n_samples: int = 0  # channel samples read (excluding time and distance)
    n_bytes: int = 0  # bytes of the data files read

    @property
    def name(self) -> str:
        return str(self.manifest["name"])


# -- manifest ----------------------------------------------------------------------------
def _schema() -> dict:
    return json.loads(SCHEMA_PATH.read_text())


def _json_path(path) -> str:
    out = ""
    for p in path:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out or "(top level)"


def load_manifest(folder: Path) -> dict[str, Any]:
    """Parse and schema-check ``campaign.json``; errors name the file and the JSON path."""
    from jsonschema import Draft202012Validator
    from jsonschema.exceptions import best_match

    path = folder / MANIFEST
    if not folder.is_dir():
        raise CampaignFormatError("campaign folder does not exist", file=str(folder))
    if not path.is_file():
        raise CampaignFormatError("manifest missing", file=str(path))
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise CampaignFormatError(f"malformed JSON at line {exc.lineno}, column {exc.colno}: "
                                  f"{exc.msg}", file=MANIFEST) from None
    except UnicodeDecodeError as exc:
        raise CampaignFormatError(f"not UTF-8 text: {exc}", file=MANIFEST) from None
    errors = list(Draft202012Validator(_schema()).iter_errors(manifest))
    if errors:
        err = best_match(errors)
        raise CampaignFormatError(f"schema violation: {err.message}", file=MANIFEST,
                                  field=_json_path(err.absolute_path))
    return manifest


def _check_manifest(manifest: dict[str, Any], folder: Path) -> None:
    """Cross-reference checks the JSON Schema cannot express."""
    def bad(fld: str, msg: str) -> CampaignFormatError:
        return CampaignFormatError(msg, file=MANIFEST, field=fld)

    names: set[str] = set()
    for i, ch in enumerate(manifest["channels"]):
        kind, pos, name, unit = ch["kind"], ch["position"], ch["name"], ch["unit"]
        if name in names:
            raise bad(f"channels[{i}].name", f"duplicate channel name {name!r}")
        names.add(name)
        if name != f"{kind}_{pos}":
            raise bad(f"channels[{i}].name",
                      f"channel name {name!r} must be kind_position = {kind}_{pos!s}")
        allowed_pos = WHEEL_POSITIONS if kind in ("Y", "Q") else BODY_POSITIONS
        if pos not in allowed_pos:
            raise bad(f"channels[{i}].position",
                      f"position {pos!r} is not valid for kind {kind!r} (allowed: {allowed_pos})")
        if unit not in UNITS_BY_KIND[kind]:
            raise bad(f"channels[{i}].unit", f"unknown unit {unit!r} for kind {kind!r}; known: "
                      f"{sorted(UNITS_BY_KIND[kind])}")
    boundary = float(manifest.get("zone1_min_radius_m", 5000.0))
    ids: set[str] = set()
    for i, s in enumerate(manifest["sections"]):
        if s["id"] in ids:
            raise bad(f"sections[{i}].id", f"duplicate section id {s['id']!r}")
        ids.add(s["id"])
        ev = s["evaluated"]
        if not ev["start_m"] < ev["end_m"]:
            raise bad(f"sections[{i}].evaluated",
                      f"start_m {ev['start_m']} must be below end_m {ev['end_m']}")
        try:
            zone_for_radius(s.get("radius_m") or 0.0, boundary, s.get("zone"))
        except InvalidParameter as exc:
            raise bad(f"sections[{i}].radius_m", str(exc)) from None
        _data_path(folder, s["measured"], f"sections[{i}].measured")
    confs = manifest.get("configurations", [])
    cnames: dict[str, int] = {}
    for i, c in enumerate(confs):
        if c["name"] in cnames:
            raise bad(f"configurations[{i}].name", f"duplicate configuration name {c['name']!r}")
        cnames[c["name"]] = i
    for i, c in enumerate(confs):
        parent = c.get("parent")
        if parent is not None and parent not in cnames:
            raise bad(f"configurations[{i}].parent",
                      f"unknown parent configuration {parent!r}; configurations: {sorted(cnames)}")
        seen, cur = {c["name"]}, parent
        while cur is not None:
            if cur in seen:
                raise bad(f"configurations[{i}].parent",
                          f"parent chain of {c['name']!r} is a cycle through {cur!r}")
            seen.add(cur)
            cur = confs[cnames[cur]].get("parent")
        for sid, rel in c["files"].items():
            if sid not in ids:
                raise bad(f"configurations[{i}].files.{sid}",
                          f"unknown section {sid!r}; sections: {sorted(ids)}")
            _data_path(folder, rel, f"configurations[{i}].files.{sid}")


def _data_path(folder: Path, rel: str, fld: str) -> Path:
    path = (folder / rel).resolve()
    if not path.is_relative_to(folder.resolve()):
        raise CampaignFormatError(f"data file {rel!r} lies outside the campaign folder",
                                  file=MANIFEST, field=fld)
    if not path.is_file():
        raise CampaignFormatError(f"data file does not exist (referenced by {fld})",
                                  file=rel, field=fld)
    return path


# -- data files --------------------------------------------------------------------------
def _read_recording(folder: Path, rel: str, section: dict, configuration: str | None,
                    units: dict[str, tuple[str, str, float]],
                    allowed: set[str], stamp: str) -> ValidatedRecording:
    table = read_table(folder / rel)
    for required in ("time_s", "distance_m"):
        if required not in table:
            raise CampaignFormatError(f"required column {required!r} missing; columns: "
                                      f"{list(table)}", file=rel, field=required)
    chans = {k: v for k, v in table.items() if k not in ("time_s", "distance_m")}
    try:
        unknown = sorted(set(chans) - set(units))
        if unknown:
            raise RecordingProblem(unknown[0], f"unknown channel column {unknown[0]!r}; the "
                                   f"manifest declares {sorted(units)}")
        extra = sorted(set(chans) - allowed)
        if extra:
            raise RecordingProblem(extra[0], f"channel {extra[0]!r} is not in the measurement "
                                   f"of section {section['id']!r} (it has {sorted(allowed)})")
        fs = check_recording(table["time_s"], table["distance_m"], chans, allowed)
    except RecordingProblem as exc:
        raise CampaignFormatError(str(exc), file=rel, field=exc.field) from None
    if configuration is None:
        d = table["distance_m"]
        ev = section["evaluated"]
        if ev["start_m"] < d[0] or ev["end_m"] > d[-1]:
            raise CampaignFormatError(
                f"evaluated range {ev['start_m']}–{ev['end_m']} m of section {section['id']!r} "
                f"is not inside the recorded distance {d[0]:.3f}–{d[-1]:.3f} m",
                file=rel, field="distance_m")
    dblob, dsha = codec.encode(np.asarray(table["distance_m"], dtype=np.float64))
    rec = ValidatedRecording(
        section_id=section["id"], configuration=configuration, file=rel, fs=fs,
        t0=float(table["time_s"][0]), n=int(table["time_s"].shape[0]),
        distance_blob=dblob, distance_sha256=dsha,
    )
    for name, values in chans.items():
        unit_in, unit, factor = units[name]
        a = np.asarray(values, dtype=np.float64)
        if factor != 1.0:
            a = a * factor
        blob, sha = codec.encode(a)
        prov: dict[str, Any] = {"source": "import", "file": rel, "column": name,
                                "imported_at": stamp, "unit": unit}
        if factor != 1.0:
            prov["unit_conversion"] = {"from": unit_in, "to": unit, "factor": factor}
        rec.signals[name] = (blob, sha, prov)
    return rec


def validate_campaign_folder(folder: str | Path, progress: Progress | None = None) -> ValidatedCampaign:
    """Check everything in ``folder``; return the validated, encoded campaign. Writes nothing."""
    folder = Path(folder)
    manifest = load_manifest(folder)
    _check_manifest(manifest, folder)
    units = {}
    for ch in manifest["channels"]:
        canonical, factor = UNITS_BY_KIND[ch["kind"]][ch["unit"]]
        units[ch["name"]] = (ch["unit"], canonical, factor)
    stamp = dt.datetime.now(dt.UTC).isoformat(timespec="seconds")
    jobs: list[tuple[str, dict, str | None]] = [(s["measured"], s, None) for s in manifest["sections"]]
    by_id = {s["id"]: s for s in manifest["sections"]}
    for c in manifest.get("configurations", []):
        jobs += [(rel, by_id[sid], c["name"]) for sid, rel in c["files"].items()]
    out = ValidatedCampaign(folder=folder, manifest=manifest, recordings=[])
    measured_channels: dict[str, set[str]] = {}
    for k, (rel, section, conf) in enumerate(jobs):
        allowed = set(units) if conf is None else measured_channels[section["id"]]
        rec = _read_recording(folder, rel, section, conf, units, allowed, stamp)
        if conf is None:
            measured_channels[section["id"]] = set(rec.signals)
        out.recordings.append(rec)
        out.n_samples += rec.n * len(rec.signals)
        out.n_bytes += (folder / rel).stat().st_size
        if progress is not None:
            progress(k + 1, len(jobs), rel)
    return out


# -- writing -----------------------------------------------------------------------------
def write_validated(session: Session, vc: ValidatedCampaign) -> Campaign:
    """Add a validated campaign to ``session`` (the caller's transaction) and flush."""
    m = vc.manifest
    if session.scalar(select(Campaign.id).where(Campaign.name == m["name"])) is not None:
        raise CampaignFormatError(f"a campaign named {m['name']!r} already exists in the "
                                  "database", file=MANIFEST, field="name")
    camp = Campaign(name=m["name"], description=m.get("description", ""),
                    zone1_min_radius_m=float(m.get("zone1_min_radius_m", 5000.0)), manifest=m)
    v = m["vehicle"]
    camp.vehicle = Vehicle(name=v.get("name", ""), kind=v["kind"],
                           secondary_suspension=bool(v.get("secondary_suspension", True)),
                           Q0_kN=float(v["Q0_kN"]), template=v.get("template", ""),
                           parameters=v.get("parameters", {}))
    chans = {}
    for ch in m["channels"]:
        canonical = UNITS_BY_KIND[ch["kind"]][ch["unit"]][0]
        chans[ch["name"]] = Channel(name=ch["name"], kind=ch["kind"], position=ch["position"],
                                    unit=canonical)
        camp.channels.append(chans[ch["name"]])
    sections = {}
    for s in m["sections"]:
        radius = s.get("radius_m")
        sections[s["id"]] = Section(
            section_id=s["id"], country=s.get("country", ""),
            radius_m=0.0 if radius is None or (isinstance(radius, float) and math.isinf(radius))
            else float(radius),
            cant_mm=float(s.get("cant_mm", 0.0)), speed_kmh=float(s["speed_kmh"]),
            curve_direction=int(s.get("curve_direction", 1)), zone_override=s.get("zone"),
            eval_start_m=float(s["evaluated"]["start_m"]), eval_end_m=float(s["evaluated"]["end_m"]),
            layout=s.get("layout"),
        )
        camp.sections.append(sections[s["id"]])
    confs: dict[str, Configuration] = {}
    for c in m.get("configurations", []):
        confs[c["name"]] = Configuration(
            name=c["name"], effects=c.get("effects", {}), parameters=c.get("parameters", {}),
            description=c.get("description", ""))
        camp.configurations.append(confs[c["name"]])
    for c in m.get("configurations", []):
        if c.get("parent") is not None:
            confs[c["name"]].parent = confs[c["parent"]]
    session.add(camp)
    recs = []
    for r in vc.recordings:
        rec = Recording(section=sections[r.section_id],
                        configuration=confs[r.configuration] if r.configuration else None,
                        fs=r.fs, t0=r.t0, n=r.n, distance_blob=r.distance_blob,
                        distance_sha256=r.distance_sha256, source_file=r.file)
        session.add(rec)
        recs.append(rec)
    session.flush()
    rows = [
        {"recording_id": rec.id, "channel_id": chans[name].id, "blob": blob, "dtype": "<f8",
         "sha256": sha, "provenance": prov}
        for rec, r in zip(recs, vc.recordings, strict=True)
        for name, (blob, sha, prov) in r.signals.items()
    ]
    if rows:
        session.execute(insert(Signal), rows)
    digest = hashlib.sha256(json.dumps(m, sort_keys=True, default=str).encode("utf-8"))
    for r in sorted(row["sha256"] for row in rows):
        digest.update(r.encode("ascii"))
    audit.record(session, audit.actor_of(session), "campaign.import", f"campaign:{m['name']}",
                 None, digest.hexdigest(),
                 detail={"sections": len(sections), "configurations": sorted(confs),
                         "signals": len(rows)})
    return camp


def import_campaign(database_or_session: Any, folder: str | Path,
                    progress: Progress | None = None) -> str:
    """Validate ``folder`` and write it in one transaction; return the campaign name.

    ``database_or_session``: a :class:`railval.db.engine.Database` (a unit of work is opened and
    committed here) or an open :class:`Session` (the caller commits).
    """
    vc = validate_campaign_folder(folder, progress=progress)
    try:
        if isinstance(database_or_session, Session):
            write_validated(database_or_session, vc)
        else:
            with database_or_session.session() as session:
                write_validated(session, vc)
    except IntegrityError as exc:  # a concurrent import of the same name won the race
        raise CampaignFormatError(f"database rejected the campaign: {exc.orig}",
                                  file=MANIFEST, field="name") from None
    return vc.name

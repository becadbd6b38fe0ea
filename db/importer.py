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
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy import insert, select
from sqlalchemy.exc import IntegrityError as UniqueViolation
from sqlalchemy.orm import Session

from railval.core.errors import CampaignFormatError, InvalidParameter
from railval.core.names import NAME_PATTERN, name_problem
from railval.core.types import BODY_POSITIONS, CHANNEL_KINDS, WHEEL_POSITIONS
from railval.core.zones import zone_for_radius
from railval.db import audit, codec, integrity, repo
from railval.db.campaigns import check_campaign_name
from railval.db.checks import (
    RecordingProblem,
    check_magnitudes,
    check_recording,
    check_units_plausible,
)
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


#: limits of the manifest parser (each named in its error message)
MANIFEST_MAX_BYTES = 16 * 1024 * 1024
MANIFEST_MAX_DEPTH = 64
NUMBER_MAX_CHARS = 40

_JSON_TOKEN = re.compile(
    r'"(?:[^"\\]|\\.)*"'  # a string (skipped)
    r"|(?P<open>[\[{])|(?P<close>[\]}])"
    r"|(?P<const>-?Infinity|NaN)"
    r"|(?P<number>-?\d+(?:\.\d+)?(?:[eE][+-]?\d+)?)"
)


def _position(text: str, offset: int) -> str:
    line = text.count("\n", 0, offset) + 1
    col = offset - (text.rfind("\n", 0, offset) + 1) + 1
    return f"line {line}, column {col}"


def _scan_json(text: str) -> None:
    """Refuse what ``json.loads`` would accept silently or choke on: NaN/Infinity literals,
    numbers that overflow a float (``1e400``) or are absurdly long, and nesting deeper than
    :data:`MANIFEST_MAX_DEPTH`. Errors name line and column."""
    depth = 0
    for m in _JSON_TOKEN.finditer(text):
        kind = m.lastgroup
        if kind is None:
            continue
        if kind == "open":
            depth += 1
            if depth > MANIFEST_MAX_DEPTH:
                raise CampaignFormatError(
                    f"nesting deeper than {MANIFEST_MAX_DEPTH} levels at "
                    f"{_position(text, m.start())} (limit MANIFEST_MAX_DEPTH)", file=MANIFEST)
        elif kind == "close":
            depth -= 1
        elif kind == "const":
            raise CampaignFormatError(
                f"{m.group()} at {_position(text, m.start())} is not a number JSON allows; "
                "write a finite number (or null where the format allows it)", file=MANIFEST)
        else:
            token = m.group()
            if len(token) > NUMBER_MAX_CHARS:
                raise CampaignFormatError(
                    f"number of {len(token)} characters at {_position(text, m.start())} "
                    f"(limit NUMBER_MAX_CHARS = {NUMBER_MAX_CHARS})", file=MANIFEST)
            if not math.isfinite(float(token)):
                raise CampaignFormatError(
                    f"number {token} at {_position(text, m.start())} is beyond the float "
                    "range (±1.8e308); write a finite number", file=MANIFEST)


def _no_duplicate_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise CampaignFormatError(
                f"duplicate key {key!r} in one JSON object (keys there: "
                f"{[k for k, _ in pairs][:10]}); a key may appear once", file=MANIFEST)
        out[key] = value
    return out


def _check_strings(value: Any, path: list) -> None:
    """No NUL anywhere (keys included): PostgreSQL text and JSON cannot hold it."""
    if isinstance(value, str):
        if "\x00" in value:
            raise CampaignFormatError("text holds a NUL character (U+0000)", file=MANIFEST,
                                      field=_json_path(path))
    elif isinstance(value, dict):
        for k, v in value.items():
            if "\x00" in k:
                raise CampaignFormatError(f"key {k!r} holds a NUL character (U+0000)",
                                          file=MANIFEST, field=_json_path(path))
            _check_strings(v, [*path, k])
    elif isinstance(value, list):
        for i, v in enumerate(value):
            _check_strings(v, [*path, i])


def _schema_message(err) -> str:
    pattern = err.schema.get("pattern") if isinstance(err.schema, dict) else None
    if err.validator == "pattern" and pattern == NAME_PATTERN:
        return f"{err.instance!r} {name_problem(err.instance)}"
    if err.validator == "pattern":
        bad = next((ch for ch in str(err.instance) if ord(ch) < 32 or ord(ch) == 127), None)
        if bad is not None:
            return f"{err.instance!r} holds the control character U+{ord(bad):04X}"
    if err.validator == "maxLength":
        return (f"text of {len(err.instance)} characters is longer than the limit "
                f"{err.validator_value} (the size of its database column)")
    return err.message


def load_manifest(folder: Path) -> dict[str, Any]:
    """Parse and schema-check ``campaign.json``; errors name the file and the JSON path."""
    from jsonschema import Draft202012Validator
    from jsonschema.exceptions import best_match

    path = folder / MANIFEST
    if not folder.is_dir():
        raise CampaignFormatError("campaign folder does not exist", file=str(folder))
    if not path.is_file():
        raise CampaignFormatError("manifest missing", file=str(path))
    size = path.stat().st_size
    if size > MANIFEST_MAX_BYTES:
        raise CampaignFormatError(f"manifest is {size} bytes, the limit MANIFEST_MAX_BYTES is "
                                  f"{MANIFEST_MAX_BYTES}", file=MANIFEST)
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise CampaignFormatError(f"not UTF-8 text: {exc}", file=MANIFEST) from None
    _scan_json(text)
    try:
        manifest = json.loads(text, object_pairs_hook=_no_duplicate_keys)
    except json.JSONDecodeError as exc:
        raise CampaignFormatError(f"malformed JSON at line {exc.lineno}, column {exc.colno}: "
                                  f"{exc.msg}", file=MANIFEST) from None
    except (ValueError, RecursionError) as exc:  # e.g. an integer beyond Python's digit limit
        raise CampaignFormatError(f"cannot parse the manifest: {exc}", file=MANIFEST) from None
    _check_strings(manifest, [])
    errors = list(Draft202012Validator(_schema()).iter_errors(manifest))
    if errors:
        err = best_match(errors)
        raise CampaignFormatError(f"schema violation: {_schema_message(err)}", file=MANIFEST,
                                  field=_json_path(err.absolute_path))
    return manifest


def _check_manifest(manifest: dict[str, Any], folder: Path) -> None:
    """Cross-reference checks the JSON Schema cannot express."""
    def bad(fld: str, msg: str) -> CampaignFormatError:
        return CampaignFormatError(msg, file=MANIFEST, field=fld)

    try:  # digits only would be read as another campaign's id (db/campaigns.get_campaign)
        check_campaign_name(manifest["name"])
    except InvalidParameter as exc:
        raise bad("name", str(exc)) from None
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
    _check_vehicle(manifest["vehicle"], bad)
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
        _check_layout(s, i)
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


def _check_vehicle(vehicle: dict[str, Any], bad: Callable[[str, str], CampaignFormatError]) -> None:
    """A vehicle naming a built-in simulator template (``coach``, ``wagon``) carries only that
    template's parameters, each inside its bounds; refused here rather than by the first
    simulation or diagnosis. Another template name is free text for an external model."""
    from railval.core.sim.vehicles import TEMPLATES, VehicleModel, unknown_parameters

    template, params = vehicle.get("template"), vehicle.get("parameters") or {}
    if template not in TEMPLATES:
        return
    unknown = unknown_parameters(template, params)
    if unknown:
        known = sorted(p.name for p in TEMPLATES[template])
        raise bad(f"vehicle.parameters.{unknown[0]}",
                  f"{', '.join(map(repr, unknown))} {'is not a parameter' if len(unknown) == 1 else 'are not parameters'} "
                  f"of vehicle template {template!r} (docs/simulator.md); known: {known}")
    try:
        VehicleModel(template, dict(params))
    except InvalidParameter as exc:
        raise bad("vehicle.parameters", str(exc)) from None


LAYOUT_KEYS = ("straight_in_m", "transition_in_m", "curve_m", "transition_out_m",
               "straight_out_m")
#: share of the evaluated range that must lie on the layout's constant-curvature part
EVALUATED_ON_CURVE_MIN = 0.5


def _check_layout(s: dict, i: int) -> None:
    """A layout's lengths are finite numbers ≥ 0; in a curve, the evaluated range lies
    (at least :data:`EVALUATED_ON_CURVE_MIN` of it) on the constant-curvature part."""
    layout = s.get("layout")
    if not layout:
        return
    fld = f"sections[{i}].layout"
    lengths = {}
    for key in LAYOUT_KEYS:
        v = layout.get(key, 0.0)
        if isinstance(v, bool) or not isinstance(v, int | float) or not (0 <= v < math.inf):
            raise CampaignFormatError(f"{key} must be a length ≥ 0 m, got {v!r}",
                                      file=MANIFEST, field=f"{fld}.{key}")
        lengths[key] = float(v)
    if not s.get("radius_m"):
        return
    lo = lengths["straight_in_m"] + lengths["transition_in_m"]
    hi = lo + lengths["curve_m"]
    ev = s["evaluated"]
    overlap = max(0.0, min(hi, ev["end_m"]) - max(lo, ev["start_m"]))
    if overlap < EVALUATED_ON_CURVE_MIN * (ev["end_m"] - ev["start_m"]):
        raise CampaignFormatError(
            f"evaluated range {ev['start_m']}–{ev['end_m']} m lies on the transitions or "
            f"straights of the layout: only {overlap:g} m of it on the constant-curvature part "
            f"{lo:g}–{hi:g} m (at least {EVALUATED_ON_CURVE_MIN:.0%} required)",
            file=MANIFEST, field=f"sections[{i}].evaluated")


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
def _read_recording(folder: Path, rel: str, section: dict, config: str | None,
                    units: dict[str, tuple[str, str, float]],
                    allowed: set[str], stamp: str, q0_kn: float,
                    skip: set[str]) -> ValidatedRecording:
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
    converted = {}
    for name, values in chans.items():
        factor = units[name][2]
        a = np.asarray(values, dtype=np.float64)
        with np.errstate(over="ignore"):  # overflow → inf, refused just below
            converted[name] = a * factor if factor != 1.0 else a
    declared = {name: units[name][0] for name in chans}
    try:
        check_magnitudes(converted, declared)
        check_units_plausible(converted, declared, q0_kn, skip)
    except RecordingProblem as exc:
        raise CampaignFormatError(str(exc), file=rel, field=exc.field) from None
    if config is None:
        d = table["distance_m"]
        ev = section["evaluated"]
        if ev["start_m"] < d[0] or ev["end_m"] > d[-1]:
            raise CampaignFormatError(
                f"evaluated range {ev['start_m']}–{ev['end_m']} m of section {section['id']!r} "
                f"is not inside the recorded distance {d[0]:.3f}–{d[-1]:.3f} m",
                file=rel, field="distance_m")
    dblob, dsha = codec.encode(np.asarray(table["distance_m"], dtype=np.float64))
    rec = ValidatedRecording(
        section_id=section["id"], configuration=config, file=rel, fs=fs,
        t0=float(table["time_s"][0]), n=int(table["time_s"].shape[0]),
        distance_blob=dblob, distance_sha256=dsha,
    )
    for name, a in converted.items():
        unit_in, unit, factor = units[name]
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
    skip = {ch["name"] for ch in manifest["channels"] if ch.get("check_unit") is False}
    stamp = dt.datetime.now(dt.UTC).isoformat(timespec="seconds")
    jobs: list[tuple[str, dict, str | None]] = [(s["measured"], s, None) for s in manifest["sections"]]
    by_id = {s["id"]: s for s in manifest["sections"]}
    for c in manifest.get("configurations", []):
        jobs += [(rel, by_id[sid], c["name"]) for sid, rel in c["files"].items()]
    out = ValidatedCampaign(folder=folder, manifest=manifest, recordings=[])
    measured_channels: dict[str, set[str]] = {}
    for k, (rel, section, conf) in enumerate(jobs):
        allowed = set(units) if conf is None else measured_channels[section["id"]]
        rec = _read_recording(folder, rel, section, conf, units, allowed, stamp,
                              float(manifest["vehicle"]["Q0_kN"]), skip)
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
    rows = _insert_signals(session, camp.name, recs, vc.recordings, chans)
    audit.record(session, audit.actor_of(session), "campaign.import", f"campaign:{m['name']}",
                 None, _content_digest(m, rows),
                 detail={"sections": len(sections), "configurations": sorted(confs),
                         "signals": len(rows)})
    return camp


def _insert_signals(session: Session, campaign: str, recs: list[Recording],
                    validated: list[ValidatedRecording],
                    chans: dict[str, Channel]) -> list[dict[str, Any]]:
    """Insert the signals of the flushed recordings ``recs`` (one per validated recording) of
    ``campaign``, each sealed with its names (:func:`railval.db.integrity.seal_signal`);
    returns the rows."""
    secret = integrity.session_secret(session)
    rows = [
        {"recording_id": rec.id, "channel_id": chans[name].id, "blob": blob, "dtype": "<f8",
         "sha256": sha,
         "provenance": {**prov, "seal": integrity.seal_signal(
             secret, rec.id, chans[name].id, sha, rec.distance_sha256, rec.fs, rec.t0, rec.n,
             names=(campaign, r.section_id, r.configuration or "", name))}}
        for rec, r in zip(recs, validated, strict=True)
        for name, (blob, sha, prov) in r.signals.items()
    ]
    if rows:
        session.execute(insert(Signal), rows)
    return rows


def _content_digest(manifest: dict[str, Any], rows: list[dict[str, Any]]) -> str:
    """SHA-256 over the canonical manifest and every content hash (the audit row's 'after')."""
    digest = hashlib.sha256(json.dumps(manifest, sort_keys=True, default=str).encode("utf-8"))
    for r in sorted(row["sha256"] for row in rows):
        digest.update(r.encode("ascii"))
    return digest.hexdigest()


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
            with database_or_session.session(write=True) as session:
                write_validated(session, vc)
    except UniqueViolation:
        # a concurrent import of the same name committed first (PostgreSQL; on SQLite the
        # write lock taken at BEGIN makes the second import see the first): same message
        # as the check in write_validated
        raise CampaignFormatError(f"a campaign named {vc.name!r} already exists in the "
                                  "database", file=MANIFEST, field="name") from None
    return vc.name


# -- a configuration's simulated files for a stored campaign -------------------------------
CONFIGURATION_MANIFEST = "configuration.json"


def _configuration_entry(folder: Path, campaign_manifest: dict[str, Any]) -> dict[str, Any]:
    """Parse ``configuration.json`` (one entry of campaign.json's ``configurations``) and
    schema-check it as such; errors name the file and the field."""
    from jsonschema import Draft202012Validator
    from jsonschema.exceptions import best_match

    path = folder / CONFIGURATION_MANIFEST
    if not path.is_file():
        raise CampaignFormatError("manifest missing (a configuration upload holds "
                                  "configuration.json and its data files)", file=CONFIGURATION_MANIFEST)
    if path.stat().st_size > MANIFEST_MAX_BYTES:
        raise CampaignFormatError(f"manifest is larger than {MANIFEST_MAX_BYTES} bytes",
                                  file=CONFIGURATION_MANIFEST)
    try:
        text = path.read_text(encoding="utf-8")
        _scan_json(text)
        entry = json.loads(text, object_pairs_hook=_no_duplicate_keys)
    except UnicodeDecodeError as exc:
        raise CampaignFormatError(f"not UTF-8 text: {exc}", file=CONFIGURATION_MANIFEST) from None
    except CampaignFormatError as exc:
        raise CampaignFormatError(str(exc).removeprefix(f"file {MANIFEST}: "),
                                  file=CONFIGURATION_MANIFEST, field=exc.field) from None
    except json.JSONDecodeError as exc:
        raise CampaignFormatError(f"malformed JSON at line {exc.lineno}, column {exc.colno}: "
                                  f"{exc.msg}", file=CONFIGURATION_MANIFEST) from None
    except (ValueError, RecursionError) as exc:
        raise CampaignFormatError(f"cannot parse the manifest: {exc}",
                                  file=CONFIGURATION_MANIFEST) from None
    _check_strings(entry, [])
    parent = entry.get("parent") if isinstance(entry, dict) else None
    probe = {**campaign_manifest, "configurations": [
        {k: v for k, v in entry.items() if k != "parent"} if isinstance(entry, dict) else entry]}
    errors = list(Draft202012Validator(_schema()).iter_errors(probe))
    if errors:
        err = best_match(errors)
        where = _json_path(err.absolute_path).removeprefix("configurations[0]").lstrip(".")
        raise CampaignFormatError(f"schema violation: {_schema_message(err)}",
                                  file=CONFIGURATION_MANIFEST, field=where or None)
    if parent is not None and not isinstance(parent, str):
        raise CampaignFormatError("parent must be a configuration name or null",
                                  file=CONFIGURATION_MANIFEST, field="parent")
    return entry


def validate_configuration_folder(session: Session, campaign: str, folder: str | Path,
                                  progress: Progress | None = None
                                  ) -> tuple[Campaign, dict[str, Any], list[ValidatedRecording]]:
    """Check a configuration's files against the stored campaign ``campaign`` (its channels,
    units, sections, the measured channels of each section, Q0) with the checks of a campaign
    import. Writes nothing."""
    folder = Path(folder)
    camp = repo.get_campaign(session, campaign)
    m = camp.manifest
    entry = _configuration_entry(folder, m)
    name = entry["name"]
    if any(c.name == name for c in camp.configurations):
        raise CampaignFormatError(f"campaign {camp.name!r} already has a configuration named "
                                  f"{name!r}", file=CONFIGURATION_MANIFEST, field="name")
    parent = entry.get("parent")
    if parent is not None and not any(c.name == parent for c in camp.configurations):
        raise CampaignFormatError(
            f"unknown parent configuration {parent!r}; campaign {camp.name!r} has "
            f"{sorted(c.name for c in camp.configurations)}", file=CONFIGURATION_MANIFEST,
            field="parent")
    by_id = {s["id"]: s for s in m["sections"]}
    measured: dict[str, set[str]] = {s.section_id: set() for s in camp.sections}
    for sid, cname in session.execute(  # the channels each section's measurement holds
            select(Section.section_id, Channel.name)
            .join(Recording, Recording.section_id == Section.id)
            .join(Signal, Signal.recording_id == Recording.id)
            .join(Channel, Signal.channel_id == Channel.id)
            .where(Section.campaign_id == camp.id, Recording.configuration_id.is_(None))):
        measured[sid].add(cname)
    units = {}
    for ch in m["channels"]:
        canonical, factor = UNITS_BY_KIND[ch["kind"]][ch["unit"]]
        units[ch["name"]] = (ch["unit"], canonical, factor)
    skip = {ch["name"] for ch in m["channels"] if ch.get("check_unit") is False}
    stamp = dt.datetime.now(dt.UTC).isoformat(timespec="seconds")
    out = []
    files = list(entry["files"].items())
    for k, (sid, rel) in enumerate(files):
        if sid not in by_id:
            raise CampaignFormatError(f"unknown section {sid!r}; sections: {sorted(by_id)}",
                                      file=CONFIGURATION_MANIFEST, field=f"files.{sid}")
        _data_path(folder, rel, f"files.{sid}")
        out.append(_read_recording(folder, rel, by_id[sid], name, units, measured[sid], stamp,
                                   float(m["vehicle"]["Q0_kN"]), skip))
        if progress is not None:
            progress(k + 1, len(files), rel)
    return camp, entry, out


def import_configuration(database: Any, campaign: str, folder: str | Path,
                         progress: Progress | None = None) -> str:
    """Validate the configuration upload ``folder`` against the stored ``campaign`` and write
    it in one transaction (signals hashed and sealed as in a campaign import; audit row
    ``configuration.import``); returns the configuration name."""
    with database.session(write=True) as session:
        camp, entry, validated = validate_configuration_folder(session, campaign, folder, progress)
        conf = Configuration(name=entry["name"], effects=entry.get("effects", {}),
                             parameters=entry.get("parameters", {}),
                             description=entry.get("description", ""))
        if entry.get("parent") is not None:
            conf.parent = next(c for c in camp.configurations if c.name == entry["parent"])
        camp.configurations.append(conf)
        sections = {s.section_id: s for s in camp.sections}
        chans = {c.name: c for c in camp.channels}
        recs = []
        for r in validated:
            rec = Recording(section=sections[r.section_id], configuration=conf, fs=r.fs, t0=r.t0,
                            n=r.n, distance_blob=r.distance_blob,
                            distance_sha256=r.distance_sha256, source_file=r.file)
            session.add(rec)
            recs.append(rec)
        session.flush()
        rows = _insert_signals(session, camp.name, recs, validated, chans)
        audit.record(session, audit.actor_of(session), "configuration.import",
                     f"configuration:{camp.name}/{conf.name}", None, _content_digest(entry, rows),
                     detail={"sections": len(recs), "signals": len(rows),
                             "parent": entry.get("parent")})
        return conf.name

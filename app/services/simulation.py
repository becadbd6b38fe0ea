"""Service: simulate a configuration of a campaign with the built-in simulator and store it.

The simulator needs the campaign's vehicle record (template + parameters), the sections with
their ``layout`` records (geometry, irregularity level/seed and the measured irregularities,
see docs/simulator.md) and the measurement's sampling rate and channel names; all come from
the database through :mod:`railval.db.repo`.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from railval.app.services.batch import BatchExecutor
from railval.core import lazy
from railval.core.errors import InvalidParameter, NotFound
from railval.core.sim import resolve_effects, simulate_campaign
from railval.core.sim.profiles import check_table, equivalent_conicity, parse_csv

#: deferred (railval.core.lazy): the ORM models (railval.db.repo) load with the first
#: database read
repo = lazy.module("railval.db.repo")

Progress = Callable[[str, float, dict], None]


def simulation_inputs(session: Any, campaign: Any) -> dict[str, Any]:
    """Extra keyword arguments for :func:`railval.core.sim.simulate_campaign` beyond vehicle, sections,
    layouts, effects, parameters, channels and fs: none — the measured irregularities travel in
    the sections' layout records. (Read by :func:`railval.app.services.campaign_context.load_context`.)"""
    return {}


def contact_geometry_file(path: str) -> dict[str, Any]:
    """The template parameter ``contact_geometry`` from a rolling-radius difference file
    (``y_mm,delta_r_mm[,delta_gamma_rad]``, docs/simulator.md "Contact geometry as data"):
    the checked table with its file name and SHA-256. Raises
    :class:`railval.core.errors.InvalidParameter` naming the file (and line) when it cannot be
    read or is malformed — before anything is simulated or stored."""
    p = Path(path)
    try:
        raw = p.read_bytes()
        text = raw.decode("utf-8-sig")
    except OSError as exc:
        raise InvalidParameter(f"contact geometry file {str(p)!r} cannot be read: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise InvalidParameter(f"contact geometry file {str(p)!r}: not UTF-8 text ({exc.reason} at byte "
                               f"{exc.start})") from None
    table = parse_csv(text, p.name)
    return {**table.to_dict(), "sha256": hashlib.sha256(raw).hexdigest()}


def simulate_configuration(database: Any, campaign: str, name: str, *, parent: str | None = None,
                           effects: Mapping[str, Mapping[str, float]] | None = None,
                           parameters: Mapping[str, float] | None = None, description: str | None = None,
                           replace: bool = False, workers: int | None = None,
                           scheduler: str | None = None, progress: Progress | None = None,
                           calibration: Mapping[str, Any] | None = None) -> dict:
    """Simulate every section of ``campaign`` with ``effects`` (and vehicle ``parameters``
    overrides, ``model.NAME`` or ``NAME``), store the result as configuration ``name`` (parent
    ``parent``) and return a summary. With a ``parent``, its effects and parameters are the
    starting point and ``effects``/``parameters`` are added on top. ``scheduler``: the
    address of a Dask scheduler that simulates the sections (results identical to a local run;
    :class:`railval.app.services.batch.BatchExecutor`). Campaign and parent are resolved once
    here (:func:`railval.db.repo.resolve`). ``calibration``: the sections its parameters were
    fitted on, stored as ``Configuration.calibration`` (values taken from a diagnosis:
    :func:`railval.app.services.diagnosis.diagnosis_fit_record`)."""

    with database.session() as s:
        camp, _ = repo.resolve(s, campaign)
        repo.check_new_configuration(s, camp, name, replace=replace)  # before simulating
        vehicle = repo.vehicle_info(s, camp)
        sections = repo.section_infos(s, camp)
        layouts = repo.section_layouts(s, camp)
        measured = repo.load_signalsets(s, camp, None)
        base_eff, base_par, pref = {}, {}, None
        if parent is not None:
            _, pref = repo.resolve(s, camp, parent)
            pconf = repo.get_configuration(s, camp, pref)
            base_eff, base_par = dict(pconf.effects or {}), dict(pconf.parameters or {})
        camp_name = camp.name
    if not measured:
        raise NotFound(f"campaign {camp_name!r} has no measurement recordings")
    eff = {k: dict(v or {}) for k, v in base_eff.items()}
    for k, v in (effects or {}).items():
        eff[k] = {**eff.get(k, {}), **dict(v or {})}
    eff = resolve_effects(eff)
    par = {**base_par, **dict(parameters or {})}
    channels = sorted({c for ss in measured.values() for c in ss.channels})
    fs = {sid: ss.fs for sid, ss in measured.items()}
    secs = [sec for sec in sections if sec.id in measured]

    def cb(done: int, total: int) -> None:
        if progress:
            progress("simulate", 0.9 * done / total, {"done": done, "total": total})

    if scheduler is not None:
        with BatchExecutor(scheduler) as ex:
            sets = simulate_campaign(vehicle, secs, layouts=layouts, effects=eff, parameters=par,
                                     channels=channels, fs=fs, workers=ex.map, progress=cb)
    else:
        sets = simulate_campaign(vehicle, secs, layouts=layouts, effects=eff, parameters=par,
                                 channels=channels, fs=fs, workers=workers, progress=cb)
    if progress:
        progress("store", 0.95, {})
    desc = description or ("built-in simulator: " + (", ".join(sorted(eff)) or "no effects"))
    with database.session(write=True) as s:
        repo.store_configuration(s, camp, name, parent=pref, effects=eff, parameters=par,
                                 description=desc, signalsets=sets, replace=replace,
                                 calibration=dict(calibration) if calibration else None)
    if progress:
        progress("done", 1.0, {})
    out = {"campaign": camp_name, "configuration": name, "parent": parent, "effects": eff,
           "parameters": par, "sections": len(sets),
           "calibration": dict(calibration) if calibration else None}
    if par.get("contact_geometry"):
        out["equivalent_conicity"] = equivalent_conicity(check_table(par["contact_geometry"]))
    return out

"""The compiled kernels of a campaign run, loaded into the ``forkserver`` before it forks a
worker.

A process pool started from the Panel app's background threads (a diagnosis, a calibration,
a re-simulation, a workshop's plots) forks its workers from the ``forkserver``
(:func:`railval.app.services.batch.start_context`). The forkserver imports the modules of
:data:`railval.app.services.batch.FORKSERVER_PRELOAD`, but numba loads a kernel from its disk
cache only when it is first called — so every worker loaded the simulator's and the EN chain's
kernels again on its first task: 1.4–1.9 CPU-s a worker against 0.3–0.5 for each later campaign
run (measured in docs/diagnosis.md "Workers that start warm"), paid twice by every diagnosis
started from the browser. :func:`warm_kernels` makes one short campaign run the way a worker
does (simulate, EN values, validation, band powers); run in the forkserver, every worker it
forks starts with the kernels in memory.

Importing this module runs :func:`warm_kernels`: the forkserver's preload list takes module
names only, so this module exists to be named there (and the Dask bench's worker warm-up,
``railval.app.bench.bench_diagnose._warm_worker``, calls :func:`warm_kernels`).
"""

from __future__ import annotations

import time

from railval.app.services import campaign_context
from railval.app.services.diagnosis_ranking import _evaluate_sections
from railval.core.sim import TrackSection, VehicleModel, simulate_section
from railval.core.types import SectionInfo

#: the seconds the last :func:`warm_kernels` took in this process (None: not run)
WARMED_S: float | None = None


def warm_kernels() -> float:
    """One campaign run of a short curve (the coach at 80 km/h, 120 m evaluated) through
    :func:`railval.app.services.diagnosis_ranking._evaluate_sections` (simulation, EN values,
    validation against itself, band powers) and the calibration's
    :func:`railval.app.services.campaign_context.evaluate_effects`; nothing is written but
    numba's cache (on an installation whose kernels are not compiled yet). Returns seconds."""
    global WARMED_S
    t0 = time.perf_counter()
    info = SectionInfo("warm", 600.0, 80.0, 80.0, 3, 120.0, 240.0)
    track = TrackSection.from_info(info)
    vehicle = VehicleModel("coach")
    measured = simulate_section(vehicle, track, {}, fs_out=200.0)
    sets = {"warm": measured}
    ctx = campaign_context.CampaignContext(
        "warm", {**vehicle.to_dict(), "secondary_suspension": True}, [info], {},
        campaign_context.section_values(sets, [info]),
        campaign_context.band_sums(sets, campaign_context.DEFAULT_BANDS_HZ), list(measured.channels),
        {"warm": 200.0})
    _evaluate_sections(ctx, ({}, {}))
    campaign_context.evaluate_effects((ctx, {}, {}))
    WARMED_S = time.perf_counter() - t0
    return WARMED_S


warm_kernels()

"""Web app: first-page interactive time in Chromium and Compare-plot switching (server side).

Builds a small campaign in a temporary SQLite database: 4 sections (one per zone) of
``--seconds`` × ``--fs`` samples (default 100 s × 200 Hz = 20 000 samples per signal),
6 channels, the measurement and 2 configurations. Then:

* **switching** — the Compare page's callback (``CompareView.update``) for ``--switches``
  section × channel switches: load the sources, EN filter, Welch PSD, min-max-LTTB to 2 000
  points (tsdownsample), replace the data of the persistent Bokeh figures and serialise them
  as the server sends them: p50/p95 wall time; then 6 revisits (cached sources and filters).
  Baselines in the same run, without the state caches: the previous implementation
  (HoloViews overlays with ``downsample1d``, rendered to Bokeh models) and the same HoloViews
  plots without downsampling (20 000 points per trace).
* **first page** — ``--loads`` page loads of the app served on a loopback port (Playwright,
  Debian's Chromium): navigation → the first chart attached (the overview's zone chart, static SVG), and
  navigation → the overview complete (its section table drawn). Baseline in the same run: a
  bare FastListTemplate with one HoloViews curve. ``--cpu-load N`` repeats both with N
  busy-looping processes competing for the 2 cores (a loaded shared machine, reproducibly).
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from railval.core import lazy

#: deferred (railval.core.lazy): ``railval bench`` (the list) imports every benchmark module for its
#: docstring; what the benchmark runs loads when it runs
write_table = lazy.function("railval.db.io", "write_table")
plots = lazy.module("railval.app.plots")
build_app = lazy.function("railval.app.main", "build_app")
build_compare_objects = lazy.function("railval.app.pages.compare", "build_compare_objects")
free_port = lazy.function("railval.app.main", "free_port")
served = lazy.function("railval.app.main", "served")
connect = lazy.function("railval.db.engine", "connect")
import_campaign = lazy.function("railval.db.importer", "import_campaign")
report = lazy.module("railval.app.report")
#: third-party libraries of the benchmark's own steps, loaded when they run
hv = lazy.module("holoviews")
pn = lazy.module("panel")
mp = lazy.module("multiprocessing")
bokeh_serialization = lazy.module("bokeh.core.serialization")
playwright_sync = lazy.module("playwright.sync_api")

CHANNELS = ("Y_w1L", "Q_w1L", "Y_w1R", "Q_w1R", "ay_cb_b1", "az_cb_b1")
RADII = (0.0, 1200.0, 500.0, 300.0)  # one section per EN 14363 zone


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--seconds", type=float, default=100.0, help="section length in s (default 100)")
    parser.add_argument("--fs", type=float, default=200.0, help="sampling rate in Hz (default 200)")
    parser.add_argument("--switches", type=int, default=20, help="compare switches timed (default 20)")
    parser.add_argument("--loads", type=int, default=3, help="page loads timed (default 3)")
    parser.add_argument("--no-browser", action="store_true", help="skip the first-page measurement")
    parser.add_argument("--cpu-load", type=int, default=0, metavar="N",
                        help="also measure the first page with N busy-looping processes running")


def write_campaign(folder: Path, seconds: float, fs: float) -> None:
    """A minimal valid campaign folder: 4 sections, measured + 2 configurations."""

    rng = np.random.default_rng(7)
    n = round(seconds * fs)
    t = np.arange(n) / fs
    kernel = np.ones(9) / 9
    sections, files = [], {"baseline": {}, "variant": {}}
    for i, radius in enumerate(RADII):
        sid = f"S{i + 1:02d}"
        dist = t * 25.0
        sections.append({"id": sid, "radius_m": radius, "cant_mm": 0.0 if radius == 0 else 100.0,
                         "speed_kmh": 90.0, "evaluated": {"start_m": float(dist[n // 5]),
                                                          "end_m": float(dist[4 * n // 5])},
                         "measured": f"measured/{sid}.csv"})
        for source, gain in (("measured", 1.0), ("baseline", 0.8), ("variant", 1.1)):
            cols = {"time_s": t, "distance_m": dist}
            for ch in CHANNELS:
                base = 77.0 if ch.startswith("Q") else 0.0
                scale = 4.0 if ch[0] in "YQ" else 0.3
                noise = np.convolve(rng.standard_normal(n + 9), kernel, mode="same")[:n]
                cols[ch] = base + gain * scale * (noise + np.sin(2 * np.pi * 0.8 * t))
            rel = f"{'measured' if source == 'measured' else 'sim/' + source}/{sid}.csv"
            write_table(folder / rel, cols)
            if source != "measured":
                files[source][sid] = rel
    manifest = {
        "format": {"id": "railval-campaign", "version": 1}, "name": "bench-app",
        "vehicle": {"name": "bench coach", "kind": "passenger", "secondary_suspension": True,
                    "Q0_kN": 77.0, "template": "coach"},
        "channels": [{"name": c, "kind": c.rpartition("_")[0], "position": c.rpartition("_")[2],
                      "unit": "kN" if c[0] in "YQ" else "m/s^2"} for c in CHANNELS],
        "sections": sections,
        "configurations": [
            {"name": "baseline", "parent": None, "effects": {}, "files": files["baseline"]},
            {"name": "variant", "parent": "baseline", "effects": {}, "files": files["variant"]},
        ],
    }
    (folder / "campaign.json").write_text(json.dumps(manifest))


def _pct(values: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(values), q))


def _switching(database, switches: int) -> dict:
    template = build_app(database)
    app = template.railval_state
    page = template.railval_pages["compare"]
    page.state.configurations = ["baseline", "variant"]
    combos = [(s, c) for s in app.param.section.objects for c in CHANNELS]

    def clear_caches() -> None:
        page.state.__dict__.pop("_signal_cache", None)
        page.state.__dict__.pop("_filter_cache", None)

    def one(i: int, mode: str) -> float:
        sec, ch = combos[i % len(combos)]
        if mode != "figures":
            clear_caches()  # the HoloViews baselines ran without the state caches
        t0 = time.perf_counter()
        app.section, app.channel = sec, ch  # the Compare page is hidden: it does not refresh
        if mode == "figures":
            page.view.update(page.state)
            # what the server then sends: the new data sources, serialised
            for fig in [*page.view.series, page.view.psd]:
                for src in fig.sources:
                    bokeh_serialization.Serializer().encode(src.data)
            return time.perf_counter() - t0
        if mode == "holoviews":
            series, psd = build_compare_objects(page.state)
        else:
            sources = page.state.sources()
            series = [plots.compare_plot(page.state.series(p, sources=sources), downsample=False)
                      for p in page.state.processings()]
            psd = plots.compare_plot(page.state.psd(sources=sources))
        for obj in [*series, psd]:
            hv.render(obj, backend="bokeh")
        return time.perf_counter() - t0

    last = len(combos) - 1  # warm-up on a combination outside the timed ones (numba, imports)
    for mode in ("figures", "holoviews", "raw"):
        one(last, mode)
    fast = [one(i, "figures") for i in range(switches)]
    revisit = [one(i, "figures") for i in range(min(switches, 6))]  # cached sources/filters
    nbase = max(3, switches // 4)
    before = [one(i, "holoviews") for i in range(nbase)]
    slow = [one(i, "raw") for i in range(nbase)]
    n = len(app.backend.signals(app.campaign, None, app.section, [CHANNELS[0]]))
    points = max(len(src.data["x"]) for src in page.view.series[0].sources)
    return {"samples_per_signal": n, "traces_per_switch": 3 * 2 + 3,
            "points_per_series_trace": points,
            "p50_ms": 1e3 * _pct(fast, 50), "p95_ms": 1e3 * _pct(fast, 95),
            "revisit_p50_ms": 1e3 * _pct(revisit, 50),
            "before_holoviews_downsample1d_p50_ms": 1e3 * _pct(before, 50),
            "before_holoviews_downsample1d_p95_ms": 1e3 * _pct(before, 95),
            "baseline_no_downsampling_p50_ms": 1e3 * _pct(slow, 50),
            "baseline_no_downsampling_p95_ms": 1e3 * _pct(slow, 95)}


def _spin(stop) -> None:
    """Busy loop (a competing CPU-bound job) until ``stop`` is set."""
    x = 0
    while not stop.is_set():
        for _ in range(100_000):
            x += 1


def _first_page(database, loads: int, cpu_load: int = 0) -> dict:
    def bare():
        return pn.template.FastListTemplate(
            title="bare", main=[pn.pane.HoloViews(hv.Curve(np.arange(100.0)), sizing_mode="stretch_width")])

    def measure(browser, url, complete: str | None, n: int = loads) -> tuple[list[float], list[float]]:
        first, whole = [], []
        for _ in range(n):
            page = browser.new_page(viewport={"width": 1280, "height": 1200})
            page.route("**/fonts.googleapis.com/**", lambda route: route.abort())
            t0 = time.perf_counter()
            page.goto(url)
            # the first chart: a canvas, or the overview's zone chart (static SVG)
            page.locator("canvas, .rv-zone-chart").first.wait_for(state="attached", timeout=120_000)
            first.append(time.perf_counter() - t0)
            if complete:
                page.locator(complete).first.wait_for(state="visible", timeout=120_000)
                whole.append(time.perf_counter() - t0)
            page.close()
        return first, whole

    def both(browser, app_url, bare_url, label) -> dict:
        first, whole = measure(browser, app_url, "table.rv-sections tbody tr")
        bare_first, _ = measure(browser, bare_url, None)
        return {f"{label}median_s": statistics.median(first), f"{label}max_s": max(first),
                f"{label}overview_complete_median_s": statistics.median(whole),
                f"{label}baseline_bare_template_median_s": statistics.median(bare_first)}

    out: dict = {"loads": loads}
    with playwright_sync.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=report.find_chromium(),
                                    args=list(report.CHROMIUM_ARGS))
        port = free_port()
        server = pn.serve({"bare": bare}, port=port, address="127.0.0.1", threaded=True, show=False)
        try:
            time.sleep(0.5)
            with served(database) as url:
                cold, _ = measure(browser, url, None, n=1)  # first session after start: imports
                out["cold_first_session_s"] = cold[0]
                out.update(both(browser, url, f"http://127.0.0.1:{port}/bare", ""))
                if cpu_load > 0:
                    ctx = mp.get_context("spawn")
                    stop = ctx.Event()
                    spinners = [ctx.Process(target=_spin, args=(stop,), daemon=True) for _ in range(cpu_load)]
                    for proc in spinners:
                        proc.start()
                    try:
                        time.sleep(1.0)
                        out["cpu_load_processes"] = cpu_load
                        out.update(both(browser, url, f"http://127.0.0.1:{port}/bare", "loaded_"))
                    finally:
                        stop.set()
                        for proc in spinners:
                            proc.join(5)
        finally:
            server.stop()
            server.join(10)
            browser.close()
    return out


def run(args: argparse.Namespace) -> dict:
    with tempfile.TemporaryDirectory(prefix="railval-bench-app-") as tmp:
        root = Path(tmp)
        write_campaign(root / "campaign", args.seconds, args.fs)
        database = connect(f"sqlite:///{root / 'bench.db'}")
        database.init()
        import_campaign(database, root / "campaign")
        out = {"compare_switch": _switching(database, args.switches)}
        if not args.no_browser:
            try:
                report.find_chromium()
                out["first_page"] = _first_page(database, args.loads, args.cpu_load)
            except report.ReportError as exc:
                out["first_page"] = {"skipped": str(exc)}
        database.dispose()
    return out

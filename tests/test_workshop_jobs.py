"""Workshop creation as a job, below the browser: the reusable render figure and the
process pool give the same PNG bytes as a figure made for each plot, identical plots are
rendered once, the job list is per user, a failed creation leaves nothing stored, the CLI
reports progress on stderr and keeps its --json document (docs/workshops.md "Creating a
workshop as a job", "Rendering speed")."""

from __future__ import annotations

import io
import json
import threading
import time

import numpy as np
import pytest
from PIL import Image
from railval.app.bench.bench_workshop import legacy_png
from railval.app.services import workshop_canvas as wc
from railval.app.services import workshop_render as wr
from railval.app.services import workshops as ws
from railval.app.state import jobs
from railval.core.errors import InvalidParameter
from railval.core.workshop import AxisRange, Scale
from railval.db import workshops as wsdb


def _specs(n: int) -> list[wr.PlotSpec]:
    """``n`` different plots: time plots of two ranges and logarithmic PSD plots."""
    rng = np.random.default_rng(7)
    out = []
    for i in range(n):
        x = np.linspace(0.0, 400.0 + 50 * (i % 3), 900)
        if i % 3 == 2:  # PSD-like, log y
            f = np.linspace(0.1, 20.0, 200)
            ym = 1e-2 / (1 + f ** 2) * (1 + 0.3 * rng.random(200))
            ys = ym * (1 + 0.2 * rng.standard_normal(200)) ** 2
            scale = Scale(AxisRange(0.0, 20.0, 5.0), AxisRange(1e-6, 1e-1, 10.0, log=True))
            out.append(wr.PlotSpec(f, ym, f, ys, scale, f"PSD plot {i}", "frequency in Hz",
                                   "PSD in (m/s²)²/Hz"))
            continue
        ym = 20 * np.sin(x / (30 + i)) + rng.standard_normal(x.size)
        ys = ym + 3 * np.cos(x / 17)
        hi = 40.0 if i % 2 else 30.0
        scale = Scale(AxisRange(0.0, 500.0, 100.0), AxisRange(-hi, hi, 10.0))
        out.append(wr.PlotSpec(x, ym, x, ys, scale, f"Guiding force Y, plot {i} — Ä ß",
                               "distance in m", "guiding force Y in kN"))
    return out


def _ref(spec: wr.PlotSpec) -> bytes:
    """The plot as render version 1 drew it (a figure per plot, matplotlib's PNG writer)."""
    return legacy_png(spec.x_meas, spec.y_meas, spec.x_sim, spec.y_sim, spec.scale,
                      title=spec.title, x_label=spec.x_label, y_label=spec.y_label)


def _pixels(png: bytes) -> np.ndarray:
    """The RGB pixels of a PNG as Pillow decodes it (a decoder independent of ours)."""
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))


def _same_pixels(a: list[bytes], b: list[bytes]) -> bool:
    return len(a) == len(b) and all(np.array_equal(_pixels(x), _pixels(y))
                                    for x, y in zip(a, b, strict=True))


def test_reused_figure_and_blitted_background_give_the_pixels_of_a_fresh_figure():
    """Render version 2 (static parts blitted, own PNG writer) draws exactly the pixels of
    a figure made for each plot and saved by matplotlib (render version 1); the bytes differ
    (RGB, Up filter, zlib level 1) but are the same for the same inputs."""
    specs = _specs(9)
    # drawn one after the other on the thread's reused figures (linear and log interleaved,
    # two y ranges: backgrounds are reused and switched)
    reused = [wr.render_png(s.x_meas, s.y_meas, s.x_sim, s.y_sim, s.scale, title=s.title,
                            x_label=s.x_label, y_label=s.y_label) for s in specs]
    assert _same_pixels(reused, [_ref(s) for s in specs])
    assert len(set(reused)) == len(reused)  # nine different plots
    again = [wc.render_fresh(s.x_meas, s.y_meas, s.x_sim, s.y_sim, s.scale, title=s.title,
                             x_label=s.x_label, y_label=s.y_label) for s in reversed(specs)]
    assert again[::-1] == reused  # deterministic: same inputs, same bytes, in any order


def test_encode_png_is_a_valid_png_of_exactly_the_pixels():
    rng = np.random.default_rng(3)
    rgba = np.full((7, 5, 4), 255, np.uint8)
    rgba[..., :3] = rng.integers(0, 256, (7, 5, 3), dtype=np.uint8)
    png = wc.encode_png(rgba)
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert np.array_equal(_pixels(png), rgba[..., :3])
    assert Image.open(io.BytesIO(png)).info["dpi"] == pytest.approx((100, 100), abs=0.01)
    rgba[0, 0, 3] = 254  # a transparent pixel would be lost in RGB: refused
    with pytest.raises(ValueError, match="transparent"):
        wc.encode_png(rgba)


def test_render_version_is_stored_and_keys_the_cache(monkeypatch):
    spec = _specs(1)[0]
    params = wr.render_parameters({"id": "k", "domain": "time"}, spec.scale, scaling="fixed",
                                  title="t", x_label="x", y_label="y", extra={})
    assert params["render_version"] == wr.RENDER_VERSION == 3
    key = wr.content_key(spec)
    monkeypatch.setattr(wr, "RENDER_VERSION", 1)
    assert wr.content_key(spec) != key  # bytes of version 1 are never served for version 2


def test_process_pool_gives_the_same_bytes_in_order_and_renders_duplicates_once(monkeypatch):
    monkeypatch.setattr(wr, "POOL_MIN_PLOTS", 4)
    wr.clear_cache()
    specs = _specs(10)
    doubled = specs + specs[:3]  # three plots twice: rendered once each
    seen: list[tuple[int, int]] = []
    out = wr.render_many(doubled, lambda d, t: seen.append((d, t)), workers=2)
    assert _same_pixels(out, [_ref(s) for s in doubled])
    assert out[10:] == out[:3]
    assert seen[-1] == (13, 13) and all(t == 13 for _, t in seen)
    assert [d for d, _ in seen] == sorted(d for d, _ in seen)
    # a second call finds every plot in the cache: nothing is rendered again
    monkeypatch.setattr(wr, "_render_chunk", lambda specs: pytest.fail("rendered again"))
    assert wr.render_many(specs) == out[:10]


def test_content_key_changes_with_every_input():
    s = _specs(1)[0]
    base = wr.content_key(s)
    y2 = s.y_sim.copy()
    y2[5] += 1e-9
    variants = [
        wr.PlotSpec(s.x_meas, s.y_meas, s.x_sim, y2, s.scale, s.title, s.x_label, s.y_label),
        wr.PlotSpec(s.x_meas, s.y_meas, s.x_sim, s.y_sim, s.scale, s.title + ".", s.x_label, s.y_label),
        wr.PlotSpec(s.x_meas, s.y_meas, s.x_sim, s.y_sim,
                    Scale(s.scale.x, AxisRange(-50.0, 50.0, 10.0)), s.title, s.x_label, s.y_label),
        wr.PlotSpec(s.x_meas, s.y_meas, s.x_sim, s.y_sim.astype(np.float32), s.scale, s.title,
                    s.x_label, s.y_label),
    ]
    assert len({base, *(wr.content_key(v) for v in variants)}) == 5


# -------------------------------------------------------------------------- job list
def test_job_list_is_per_user_and_keeps_the_error():
    gate = threading.Event()

    def work(progress):
        progress("plots rendered 3 of 9", 0.6, {"done": 3, "total": 9})
        gate.wait(10)
        raise InvalidParameter("no plot for this choice")

    rec = jobs.start_tracked("alice-jl", "Create workshop J1", work, link="/workshops/J1",
                             workshop="J1")
    deadline = time.monotonic() + 10
    while jobs.jobs_of("alice-jl")[0]["done"] != 3 and time.monotonic() < deadline:
        time.sleep(0.02)
    mine = jobs.jobs_of("alice-jl")
    assert [(j["title"], j["state"], j["done"], j["total"]) for j in mine] == [
        ("Create workshop J1", "running", 3, 9)]
    assert jobs.jobs_of("bob-jl") == []  # another user sees nothing of it
    with pytest.raises(InvalidParameter, match="already being created"):
        jobs.start_tracked("bob-jl", "Create workshop J1", work, link="/x", workshop="J1")
    gate.set()
    while jobs.jobs_of("alice-jl")[0]["state"] == "running" and time.monotonic() < deadline:
        time.sleep(0.02)
    done = jobs.workshop_job("alice-jl", "J1")
    assert done["state"] == "failed" and "no plot for this choice" in done["error"]
    assert jobs.workshop_job("bob-jl", "J1") is None and rec.ended is not None


# -------------------------------------------------------------------------- creation
@pytest.fixture(scope="module")
def db(tmp_path_factory):
    from tests.browser_support import demo_database

    database = demo_database(tmp_path_factory.mktemp("wsjobs"), n_configs=2)
    yield database
    database.dispose()


def test_creation_reports_plots_rendered_n_of_n_and_stores_the_same_images(db, monkeypatch):
    monkeypatch.setattr(wr, "POOL_MIN_PLOTS", 4)
    wr.clear_cache()
    calls = []
    out = ws.create(db, "JP", "demo", sections=["S01", "S02"], kinds=["Y_time", "ay_cb_psd"],
                    repeats=0.0, progress=lambda stage, f, info=None: calls.append((stage, f, info)))
    n = out["plots"]
    rendered = [c for c in calls if c[0] == "rendering plots"]
    assert rendered[-1] == ("rendering plots", 1.0, {"done": n, "total": n})
    assert [c[2]["done"] for c in rendered] == sorted(c[2]["done"] for c in rendered)
    # the same workshop rendered in this process alone, without the cache: the same bytes
    wr.clear_cache()
    monkeypatch.setattr(wr, "RENDER_WORKERS", 1)
    ws.create(db, "JS", "demo", sections=["S01", "S02"], kinds=["Y_time", "ay_cb_psd"],
              repeats=0.0)

    def images(name):
        with db.session() as s:
            w = wsdb.get_workshop(s, name)
            return [wsdb.plot_image(s, w.id, p.id)[0] for p in wsdb.plots(s, w)]
    pool, alone = images("JP"), images("JS")
    assert len(pool) == n and pool == alone and len(set(pool)) == n


def test_failed_creation_stores_nothing(db, monkeypatch):
    def broken(specs, progress=None, **kw):
        progress(1, len(specs))
        raise RuntimeError("renderer crashed")

    monkeypatch.setattr(wr, "render_many", broken)
    with pytest.raises(RuntimeError, match="renderer crashed"):
        ws.create(db, "JF", "demo", sections=["S01"], kinds=["Y_time"], repeats=0.0)
    with db.session() as s:
        assert "JF" not in [w.name for w in wsdb.list_workshops(s)]


def test_cli_create_reports_progress_on_stderr_and_keeps_the_json(db, capsys):
    from railval.app.cli import main as cli

    url = str(db.engine.url)
    code = cli(["--db", url, "workshop", "create", "JC", "--campaign", "demo", "--sections",
                "S01", "--kinds", "Y_time", "--repeats", "0", "--json"])
    captured = capsys.readouterr()
    assert code == 0
    doc = json.loads(captured.out)
    assert doc["name"] == "JC" and doc["stored"] is True and doc["plots"] == 4
    assert "[100.0 %] rendering plots 4/4" in captured.err  # progress on stderr only


def test_a_long_title_and_the_last_x_tick_label_stay_inside_the_plot():
    """A title naming a long vehicle and configuration is wrapped onto at most three lines
    that fit above the axes, and the last x tick label ("2000") lies within the figure
    (render versions 1 and 2 cut both at the right edge): extents measured by matplotlib's
    own renderer on the reused figure after the plot is drawn."""
    from railval.core.workshop import PLOT_KINDS

    kind = next(iter(PLOT_KINDS.values()))
    title = ws._title(kind, "w1L", blind=False, vehicle="Coach (Manchester benchmark vehicle 1 based)",
                      config="baseline+parasitic_yaw_stiffness+lateral_bumpstop+friction_damping", section="S01")
    lines = title.split("\n")
    assert 2 <= len(lines) <= 3 and lines[0].endswith("— section S01"), lines
    assert "".join(lines[1:]).replace(" ", "") == (
        "Coach (Manchester benchmark vehicle 1 based), configuration "
        "baseline+parasitic_yaw_stiffness+lateral_bumpstop+friction_damping").replace(" ", "")
    assert ws._title(kind, "w1L", blind=True, vehicle="V", config="C", section="S").count("\n") == 0
    x = np.linspace(0.0, 2000.0, 800)
    canvas = wc._Canvas(False)
    canvas.draw(x, np.sin(x / 90) * 10, x, np.cos(x / 90) * 10, Scale(AxisRange(0.0, 2000.0, 500.0),
                AxisRange(-20.0, 20.0, 10.0)), title=title, x_label="distance in m", y_label="Y in kN")
    renderer = canvas.fig.canvas.get_renderer()
    fig_box = canvas.fig.bbox
    t = canvas.title.get_window_extent(renderer)
    assert fig_box.x0 <= t.x0 and t.x1 <= fig_box.x1 and t.y1 <= fig_box.y1, (t, fig_box)
    assert t.y0 >= canvas.ax.get_window_extent(renderer).y1  # above the axes, not over the data
    last = [lab for lab in canvas.ax.get_xticklabels() if lab.get_text()][-1]
    assert last.get_text() == "2000" and last.get_window_extent(renderer).x1 <= fig_box.x1

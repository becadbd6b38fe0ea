"""Static PNG rendering of review plots (docs/workshops.md "One fixed scaling").

Each review plot is drawn once with matplotlib's Agg backend and stored as PNG bytes with
its render parameters and SHA-256; reviewers are served exactly those bytes and cannot
rescale them. Output is deterministic: fixed size and dpi, DejaVu Sans (shipped with
matplotlib), no time stamp or software version in the PNG metadata, no antialiasing
differences between runs (same library build) — the same inputs give byte-identical files.

Look (the same for every plot of a workshop): measurement drawn first (beneath) in black,
simulation on top in Okabe–Ito vermilion (the app's colours, :mod:`railval.app.scales`: a
colour-blind-safe pair; Okabe & Ito 2008, "Color Universal Design"), legend in the upper right corner, both axes labelled
with units, the kind's fixed axis ranges (:func:`railval.core.workshop.kind_scale`).
"""

from __future__ import annotations

import io
from collections.abc import Mapping
from typing import Any

import matplotlib

matplotlib.use("Agg", force=False)

import numpy as np
from matplotlib.figure import Figure
from railval.app.scales import MEASURED_COLOR, SIM_COLORS
from railval.core.workshop import Scale

#: the look of every review plot (stored with each plot's render parameters)
STYLE: dict[str, Any] = {
    "width_in": 10.0,
    "height_in": 5.6,
    "dpi": 100,
    "font": "DejaVu Sans",
    "font_size": 12,
    "title_size": 13,
    "measurement": {"label": "measurement", "color": MEASURED_COLOR, "linewidth": 1.2, "zorder": 2},
    "simulation": {"label": "simulation", "color": SIM_COLORS[0], "linewidth": 1.1, "zorder": 3},
    "legend": "upper right",
    "grid_color": "#d9d9d9",
}

_RC = {
    "font.family": "sans-serif",
    "font.sans-serif": [STYLE["font"]],
    "font.size": STYLE["font_size"],
    "axes.titlesize": STYLE["title_size"],
    "svg.hashsalt": "railval",
    "path.simplify": True,
}


def render_png(x_meas: np.ndarray, y_meas: np.ndarray, x_sim: np.ndarray, y_sim: np.ndarray,
               scale: Scale, *, title: str, x_label: str, y_label: str) -> bytes:
    """One review plot as PNG bytes (see the module docstring for the look)."""
    with matplotlib.rc_context(_RC):
        fig = Figure(figsize=(STYLE["width_in"], STYLE["height_in"]), dpi=STYLE["dpi"])
        ax = fig.add_subplot(1, 1, 1)
        ax.set_axisbelow(True)
        ax.grid(True, color=STYLE["grid_color"], linewidth=0.6)
        m, s = STYLE["measurement"], STYLE["simulation"]
        ax.plot(x_meas, y_meas, color=m["color"], linewidth=m["linewidth"], zorder=m["zorder"],
                label=m["label"])
        ax.plot(x_sim, y_sim, color=s["color"], linewidth=s["linewidth"], zorder=s["zorder"],
                label=s["label"])
        if scale.y.log:
            ax.set_yscale("log")
        else:
            ax.set_yticks(_ticks(scale.y.lo, scale.y.hi, scale.y.step))
        ax.set_xticks(_ticks(scale.x.lo, scale.x.hi, scale.x.step))
        ax.set_xlim(scale.x.lo, scale.x.hi)
        ax.set_ylim(scale.y.lo, scale.y.hi)
        ax.set_xlabel(x_label)
        ax.set_ylabel(y_label)
        ax.set_title(title, loc="left")
        ax.legend(loc=STYLE["legend"], frameon=True, framealpha=0.9)
        fig.subplots_adjust(left=0.09, right=0.98, top=0.91, bottom=0.11)
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=STYLE["dpi"], metadata={"Software": None})
    return buf.getvalue()


def _ticks(lo: float, hi: float, step: float) -> np.ndarray:
    n = round((hi - lo) / step)
    return np.round(lo + step * np.arange(n + 1), 12)


def render_parameters(kind: Mapping[str, Any], scale: Scale, *, scaling: str, title: str,
                      x_label: str, y_label: str, extra: Mapping[str, Any]) -> dict[str, Any]:
    """The JSON stored with a plot: everything that decides its pixels."""
    return {"kind": kind["id"], "domain": kind["domain"], "scaling": scaling,
            "scale": scale.to_dict(), "title": title, "x_label": x_label, "y_label": y_label,
            "style": STYLE, "matplotlib": matplotlib.__version__, **dict(extra)}

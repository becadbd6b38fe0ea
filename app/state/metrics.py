"""State of the curve-metrics page."""

from __future__ import annotations

import pandas as pd
import param

from railval.app.state.app import AppState
from railval.core.metrics.registry import DEFAULT_FAMILIES


#: the metric family computed only on request: ISO/TS 18571 took 73–88 % of the CPU time of
#: a section on the demo (docs/metrics.md, measured cost)
ON_REQUEST_FAMILY = "iso18571"


class MetricsState(param.Parameterized):
    """Curve metrics of the selected configuration (``railval.app.services.metrics``), computed per
    section in a background job; the cost shown on the page is measured (stored runs' time)."""

    scope = param.Selector(default="selected section", objects=["selected section", "all sections"])
    view = param.Selector(default="raw", objects=["raw", "synchronised", "raw and synchronised"])
    frame = param.DataFrame(default=None, allow_None=True, doc="metrics of the last computation")
    computed_for = param.String(default="", doc="what ``frame`` holds (campaign/config/scope)")
    runs = param.List(default=[], doc="stored metrics runs of the configuration, newest first")
    include_iso = param.Boolean(default=False, doc=(
        "also compute the ISO/TS 18571 rating (its dynamic time warping takes most of the time)"))

    ID_COLUMNS = ("section", "zone", "channel", "unit")

    def __init__(self, app: AppState, **params):
        super().__init__(**params)
        self.app = app

    def key(self) -> str:
        scope = self.app.section if self.scope == "selected section" else "all sections"
        iso = " / with ISO/TS 18571" if self.include_iso else ""
        return f"{self.app.campaign} / {self.app.configuration} / {scope}{iso}"

    def families(self) -> list[str] | None:
        """Metric families to compute: all, or all but ISO/TS 18571 unless asked for."""
        return None if self.include_iso else [f for f in DEFAULT_FAMILIES if f != ON_REQUEST_FAMILY]

    def measured_cost(self) -> tuple[float, int] | None:
        """(median seconds per section, runs) of the stored single-section runs with the
        current families: the cost this installation measured, or None before any."""
        fams = self.families()
        fams = sorted(fams) if fams is not None else None
        secs = sorted(r["seconds"] for r in self.runs
                      if len(r["settings"].get("sections") or []) == 1
                      and r["settings"].get("families") == fams and r["seconds"] > 0)
        if not secs:
            return None
        return float(secs[len(secs) // 2]), len(secs)

    def scope_sections(self) -> list[str]:
        app = self.app
        return [app.section] if self.scope == "selected section" else list(app.param.section.objects)

    def load_stored(self) -> bool:
        """Show the stored metrics of the current scope when every section of it was computed
        with the current data (a reload, a second tab, another user); True when shown."""
        app = self.app
        if not app.campaign or not app.configuration:
            return False
        self.runs = app.backend.metrics_runs(app.campaign, app.configuration)
        if not self.runs:
            return False
        frames = []
        for sid in self.scope_sections():
            df = app.backend.stored_metrics(app.campaign, app.configuration, [sid], families=self.families())
            if df is None:
                return False
            frames.append(df)
        if not frames:
            return False
        self.computed_for = self.key()
        self.frame = pd.concat(frames, ignore_index=True)
        return True

    def compute(self, dispatch=None, background: bool = True):
        app = self.app
        campaign, config = app.campaign, app.configuration
        sections = self.scope_sections()
        key = self.key()
        families = self.families()

        def work(progress):
            frames = []
            for i, sid in enumerate(sections):
                progress(i / len(sections), f"section {sid} ({i + 1}/{len(sections)})")
                frames.append(app.backend.metrics(campaign, config, [sid], families=families))
            return pd.concat(frames, ignore_index=True) if frames else None

        def done(df):
            self.runs = app.backend.metrics_runs(campaign, config)
            self.computed_for = key  # first: the view refreshes when ``frame`` changes
            self.frame = df
        return app.run_job("metrics", work, done, dispatch=dispatch, background=background,
                           action="data.read")

    def table(self):
        """The metric table in the chosen view: raw columns, synchronised columns (``*_sync``
        shown under the raw name, with the lag), or both side by side."""
        df = self.frame
        if df is None:
            return None
        ids = [c for c in self.ID_COLUMNS if c in df.columns]
        metric_cols = [c for c in df.columns if c not in ids and f"{c}_sync" in df.columns]
        # the lag and whether it is reliable (not within 5 % of the ±max_lag search bound)
        lag = ["lag_s"] + (["lag_reliable"] if "lag_reliable" in df.columns else [])
        if self.view == "raw":
            cols = ids + metric_cols
            out = df[cols]
        elif self.view == "synchronised":
            out = df[ids + lag + [f"{c}_sync" for c in metric_cols]]
            out = out.rename(columns={f"{c}_sync": c for c in metric_cols})
        else:
            cols = ids + lag + [x for c in metric_cols for x in (c, f"{c}_sync")]
            out = df[cols]
        return out.reset_index(drop=True)



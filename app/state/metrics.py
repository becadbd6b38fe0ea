"""State of the curve-metrics page."""

from __future__ import annotations

import pandas as pd
import param

from railval.app.state.app import AppState


class MetricsState(param.Parameterized):
    """Curve metrics of the selected configuration (``railval.app.services.metrics``), computed per
    section in a background job (≈ 3 s per section of 12 channels on one core)."""

    scope = param.Selector(default="selected section", objects=["selected section", "all sections"])
    view = param.Selector(default="raw", objects=["raw", "synchronised", "raw and synchronised"])
    frame = param.DataFrame(default=None, allow_None=True, doc="metrics of the last computation")
    computed_for = param.String(default="", doc="what ``frame`` holds (campaign/config/scope)")
    runs = param.List(default=[], doc="stored metrics runs of the configuration, newest first")

    ID_COLUMNS = ("section", "zone", "channel", "unit")

    def __init__(self, app: AppState, **params):
        super().__init__(**params)
        self.app = app

    def key(self) -> str:
        scope = self.app.section if self.scope == "selected section" else "all sections"
        return f"{self.app.campaign} / {self.app.configuration} / {scope}"

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
            df = app.backend.stored_metrics(app.campaign, app.configuration, [sid])
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

        def work(progress):
            frames = []
            for i, sid in enumerate(sections):
                progress(i / len(sections), f"section {sid} ({i + 1}/{len(sections)})")
                frames.append(app.backend.metrics(campaign, config, [sid]))
            return pd.concat(frames, ignore_index=True) if frames else None

        def done(df):
            self.runs = app.backend.metrics_runs(campaign, config)
            self.computed_for = key  # first: the view refreshes when ``frame`` changes
            self.frame = df
        return app.run_job("metrics", work, done, dispatch=dispatch, background=background)

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



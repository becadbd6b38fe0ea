"""Shared pieces of the page views: base class, dispatch onto the Bokeh event loop, tables."""

from __future__ import annotations

import html
from collections.abc import Callable
from typing import Any

import pandas as pd
import panel as pn
import param
from panel.io.state import set_curdoc

from railval.app import plots
from railval.app.security import plain_message
from railval.app.state import PAGE_TITLES, AppState
from railval.core.roles import PAGE_ACTIONS

TABLE_STYLE = {"font-size": "13px"}

#: button groups (time/distance, processing, scope): the selected button is filled in the
#: app's blue with white text, the others white with a blue outline, so the choice is obvious
TOGGLE_CSS = """
.bk-btn, .bk-btn.bk-btn-default { background: #ffffff !important; background-image: none !important;
                                  color: #0b5394 !important; border: 1px solid #0b5394 !important; }
.bk-btn.bk-active, .bk-btn.bk-btn-default.bk-active { background: #0b5394 !important;
                                                      color: #ffffff !important; font-weight: 600;
                                                      box-shadow: none !important; }
"""


def toggle_group(parameter: param.Parameter, label: str, **kw: Any) -> pn.Column:
    """A labelled button group for a Selector parameter: the label above (button groups show
    no title of their own) and the selected state drawn with :data:`TOGGLE_CSS`."""
    widget = pn.widgets.RadioButtonGroup.from_param(parameter, name=label, stylesheets=[TOGGLE_CSS],
                                                    **kw)
    caption = pn.pane.HTML(f"<label class='rv-label'>{html.escape(label)}</label>",
                           margin=(5, 10, 0, 10), styles={"font-size": "13px"})
    return pn.Column(caption, widget, margin=0)


def bounded_input(parameter: param.Parameter, label: str, app: Any, **kw: Any) -> pn.widgets.Widget:
    """A number input for a bounded Integer/Number parameter that never takes a value outside
    its bounds silently: a value outside is refused with a message in the status area naming
    the field, the value and the allowed range, and the field shows the kept value again."""
    owner, name = parameter.owner, parameter.name
    lo, hi = parameter.bounds or (None, None)
    integer = isinstance(parameter, param.Integer)
    cls = pn.widgets.IntInput if integer else pn.widgets.FloatInput
    widget = cls(name=label, value=getattr(owner, name), **kw)

    def text(v: float | None) -> str:
        return "no limit" if v is None else f"{v:g}"

    def typed(event) -> None:
        v = event.new
        if v is None or (lo is not None and v < lo) or (hi is not None and v > hi):
            kept = getattr(owner, name)
            app.set_status(f"{label}: {text(v) if v is not None else 'empty'} is outside the allowed range "
                           f"{text(lo)} … {text(hi)}; kept {kept:g}", "warning")
            widget.value = kept
            return
        setattr(owner, name, int(v) if integer else float(v))

    widget.param.watch(typed, ["value"])
    owner.param.watch(lambda e: setattr(widget, "value", e.new), [name])
    return widget


def make_dispatch() -> Callable[[Callable[[], None]], None]:
    """A ``dispatch`` for :meth:`AppState.run_job`: runs a state update on the session's
    event loop (Bokeh documents must only be changed there), or directly outside a server."""
    doc = pn.state.curdoc

    def dispatch(fn: Callable[[], None]) -> None:
        if doc is None or doc.session_context is None:
            fn()
            return

        def cb() -> None:
            with set_curdoc(doc):
                fn()
        doc.add_next_tick_callback(cb)
    return dispatch


def table(df: pd.DataFrame, height: int | None = None, **kw: Any) -> pn.widgets.Tabulator:
    """A read-only, sortable Tabulator with readable font and no index column."""
    opts: dict[str, Any] = {"show_index": False, "disabled": True, "sizing_mode": "stretch_width",
                                "layout": "fit_data_stretch", "stylesheets": [":host {font-size: 13px;}"]}
    if height is not None:
        opts["height"] = height
    opts.update(kw)
    return pn.widgets.Tabulator(df, **opts)


HTML_TABLE_CSS = """
table.rv-table { border-collapse: collapse; width: 100%; font-size: 13px; }
table.rv-table th { text-align: left; border-bottom: 2px solid #0b5394; padding: 5px 8px;
                    background: #f4f6f8; position: sticky; top: 0; }
table.rv-table td { padding: 4px 8px; border-bottom: 1px solid #e3e6ea; }
table.rv-table td.num { text-align: right; font-variant-numeric: tabular-nums; }
table.rv-table tr:nth-child(even) td { background: #fafbfc; }
"""


def table_markup(df: pd.DataFrame, css_class: str = "") -> str:
    """The markup of :func:`html_table`: cells escaped, numbers right-aligned."""
    numeric = {c for c in df.columns if pd.api.types.is_numeric_dtype(df[c])}
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in df.columns)
    rows = "".join(
        "<tr>" + "".join(f"<td class='num'>{html.escape(str(v))}</td>" if c in numeric
                         else f"<td>{html.escape(str(v))}</td>" for c, v in zip(df.columns, rec, strict=True))
        + "</tr>" for rec in df.itertuples(index=False))
    return (f"<table class='rv-table {html.escape(css_class)}'><thead><tr>{head}</tr></thead>"
            f"<tbody>{rows}</tbody></table>")


def html_table(df: pd.DataFrame | str, css_class: str = "", max_height: int | None = None) -> pn.pane.HTML:
    """A static HTML table (one light model, no table widget): for read-only lists shown
    on page load. Cells are escaped; numbers right-aligned. ``df`` may be the markup of
    :func:`table_markup` made before (shared by sessions)."""
    style = {"overflow-y": "auto", "max-height": f"{max_height}px"} if max_height else {}
    markup = df if isinstance(df, str) else table_markup(df, css_class)
    return pn.pane.HTML(markup, sizing_mode="stretch_width", stylesheets=[HTML_TABLE_CSS], styles=style)


DV_LABEL = "mean D_v / std limit (–)"
PSD_RATIO_LABEL = "log2 PSD ratio (–)"


def where_map(grid: Any, title: str, psd: bool = False, height: int = 330) -> pn.pane.HoloViews:
    """A "where it fails" heat map (``plots.pattern_heatmap``) of a quantity × zone grid, or
    with ``psd`` of a car body acceleration × band grid, on the fixed colour scale. Its
    categorical axes are not linked to other plots of the page (Panel would otherwise share
    the quantity axis with the bar charts' and reverse the rows)."""
    if psd:
        obj = plots.pattern_heatmap(grid, title, plots.PSD_RATIO_LIMIT, PSD_RATIO_LABEL, "frequency band",
                                    "car body acc.", height=height)
    else:
        obj = plots.pattern_heatmap(grid, title, plots.WHERE_LIMIT, DV_LABEL, "EN 14363 test zone", height=height)
    return pn.pane.HoloViews(obj, linked_axes=False, sizing_mode="stretch_width")


def message(text: str, kind: str = "info") -> pn.pane.Alert:
    return pn.pane.Alert(html.escape(text), alert_type=kind, sizing_mode="stretch_width",
                         margin=(5, 10))


class PageBase(pn.viewable.Viewer):
    """A page: ``refresh()`` rebuilds its content; it runs when the page is shown and when
    a watched selection changes while it is shown (hidden pages stay idle)."""

    name_: str = ""
    watch_app: tuple[str, ...] = ("campaign", "configuration", "revision")

    def __init__(self, app: AppState, **params):
        super().__init__(**params)
        self.app = app
        self._stale = True
        self.body = pn.Column(sizing_mode="stretch_width")
        self.header = pn.pane.Markdown(f"## {PAGE_TITLES[self.name_]}", margin=(0, 10))
        app.param.watch(self._on_app_change, list(self.watch_app))

    def show(self) -> None:
        """The page is being shown: refresh it if a watched selection changed meanwhile."""
        if self._stale:
            self.safe_refresh()

    def _on_app_change(self, *events: param.parameterized.Event) -> None:
        self._stale = True
        if self.app.page == self.name_:
            self.safe_refresh()

    def safe_refresh(self) -> None:
        """Refresh; any error is logged and shown in the page and in the status area as a plain
        message (:func:`railval.app.security.plain_message`), never raised."""
        self._stale = False
        if not self.app.page_allowed(self.name_):  # server side, whatever the browser sent
            self.body.objects = [message(self.app.denial(PAGE_ACTIONS[self.name_]), "danger")]
            return
        if self.app.campaign is None:
            self.body.objects = [message("No campaign in the database. Import one with "
                                         "`railval import DIR` or start with the demo campaign "
                                         "(`railval serve` without --no-demo).", "warning")]
            return
        try:
            self.refresh()
        except Exception as exc:  # noqa: BLE001 - UI boundary: shown in the status area
            # one way for every error: logged with its traceback, a plain sentence shown
            detail = plain_message(exc, PAGE_TITLES[self.name_])
            self.app.set_status(f"{PAGE_TITLES[self.name_]}: {detail}", "error")
            self.body.objects = [message(f"{PAGE_TITLES[self.name_]} is not available: {detail}",
                                         "danger")]

    def refresh(self) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def __panel__(self) -> pn.viewable.Viewable:
        return pn.Column(self.header, self.body, sizing_mode="stretch_width")

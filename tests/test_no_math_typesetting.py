"""User text is shown as text: no Panel pane of the app typesets ``$$…$$`` and the page's
resources leave MathJax out (app/main.py, ``no_math_typesetting``; the browser check is
tests/test_browser_security.py::test_latex_in_a_description_stays_text)."""

from __future__ import annotations

import panel as pn
from bokeh.document import Document
from bokeh.resources import Resources
from panel.io.resources import bundle_resources

import railval.app.main  # noqa: F401  (the app's set-up: what a served session sees)

LATEX = r"See $$\href{javascript:alert(1)}{\text{the report}}$$"


def test_markdown_and_alert_panes_do_not_typeset_math():
    """The panes' own switch is off (Markdown's renderer then leaves ``$$`` alone); the HTML
    pane hands it to its model. Markdown's model does not take the switch, so what keeps the
    browser from typesetting there is the missing MathJax bundle (next test)."""
    for pane in (pn.pane.Markdown(LATEX), pn.pane.Alert(LATEX), pn.pane.HTML(LATEX)):
        assert pane.disable_math is True, type(pane).__name__
        assert r"$$\href{javascript:alert(1)}" in pane.get_root(Document()).text
    assert pn.pane.HTML(LATEX).get_root(Document()).disable_math is True


def test_a_page_with_text_panes_is_sent_without_mathjax():
    """Panel adds Bokeh's MathJax bundle to every page holding an HTML model; the app's pages
    all do. Contrast: asked for explicitly, the bundle is there (the check can tell)."""
    doc = Document()
    pn.Column(pn.pane.Markdown(LATEX), pn.pane.HTML("<b>x</b>")).server_doc(doc)
    files = [str(f) for f in bundle_resources(doc.roots, Resources(mode="server")).js_files]
    assert files and not [f for f in files if "mathjax" in f.lower()], files
    with_math = bundle_resources(doc.roots, Resources(mode="server"), enable_mathjax=True).js_files
    assert [f for f in map(str, with_math) if "mathjax" in f.lower()]

"""A serving process moves its start-up objects to the collector's permanent generation before
the first session (``railval.app.upkeep.freeze_startup_objects``, docs/app.md "Sessions that
close"): the full collections Panel and railval run after sessions close then walk only what
sessions allocated. Checked in a fresh interpreter, so the test process itself is not frozen."""

from __future__ import annotations

import json
import subprocess
import sys

PROBE = r"""
import gc, json, sys
import panel as pn
import railval.app.main as m
from railval.db.engine import connect

db = connect(sys.argv[1]); db.init()
seen = {}
def fake_serve(*a, **k):  # what the real pn.serve would start on: the collector's state then
    seen["frozen_at_serve"] = gc.get_freeze_count()
    seen["threaded"] = k.get("threaded")
pn.serve = fake_serve
m.serve(db, port=0, threaded=True)          # a test serving in a thread: nothing frozen
seen["frozen_threaded"] = seen.pop("frozen_at_serve")
m.serve(db, port=0)                         # railval serve
class Node:
    pass
a, b = Node(), Node()
a.other, b.other = b, a                     # cyclic garbage made after the freeze
del a, b
seen["collected_after"] = gc.collect()
print(json.dumps(seen))
"""


def test_serve_freezes_start_up_objects_and_still_collects_sessions(tmp_path):
    url = f"sqlite:///{tmp_path / 'freeze.db'}"
    out = subprocess.run([sys.executable, "-c", PROBE, url], capture_output=True, text=True, timeout=300,
                         check=False)
    assert out.returncode == 0, out.stderr[-2000:]
    seen = json.loads(out.stdout.strip().splitlines()[-1])
    assert seen["frozen_threaded"] == 0
    # Panel, Bokeh and railval's modules: several 100 000 objects, frozen before serving
    assert seen["frozen_at_serve"] > 100_000
    # objects made after the freeze (a session's) are still collected: the two-node cycle
    assert seen["collected_after"] >= 2

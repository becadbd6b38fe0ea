"""``railval serve``: argument defaults, demo seeding rule, and a real server answering."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import urllib.request

import pytest

from railval.app.cli import build_parser
from railval.app.cli.cmd_app import seed_demo
from railval.app.main import free_port


def test_serve_defaults():
    args = build_parser().parse_args(["serve"])
    assert (args.port, args.address, args.no_demo, args.allow_websocket_origin) == (5006, "127.0.0.1", False, None)
    args = build_parser().parse_args(["serve", "--port", "8080", "--no-demo",
                                      "--allow-websocket-origin", "railval.example.org"])
    assert (args.port, args.no_demo, args.allow_websocket_origin) == (8080, True, ["railval.example.org"])


def test_demo_is_not_seeded_into_a_database_with_campaigns(tmp_path):
    from tests.browser_support import demo_database

    db = demo_database(tmp_path)
    assert seed_demo(db) == "database holds campaigns; demo not seeded"
    db.dispose()


def test_serve_migrates_an_empty_database_and_answers(tmp_path):
    url = f"sqlite:///{tmp_path / 'fresh.db'}"
    port = free_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "app", "--db", url, "serve", "--no-demo", "--port", str(port)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True,
        env={**os.environ, "PYTHONWARNINGS": "ignore"})
    try:
        deadline = time.monotonic() + 90
        while True:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/app", timeout=30) as resp:
                    body = resp.read().decode()
                    break
            except OSError:
                if proc.poll() is not None or time.monotonic() > deadline:
                    pytest.fail(f"server did not answer: {proc.stderr.read().decode()[-2000:]}")
                time.sleep(0.3)
        assert resp.status == 200 and "railval" in body
    finally:
        os.killpg(proc.pid, signal.SIGTERM)
        proc.wait(20)
        proc.stdout.close()
        proc.stderr.close()
    from railval.db.engine import connect

    db = connect(url)
    assert db.current_revision() == db.head_revision()  # migrated on start
    db.dispose()

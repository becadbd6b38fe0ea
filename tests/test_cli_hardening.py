"""The CLI as a clumsy user or a curious one meets it: clean one-line errors without
tracebacks or SQL, a private SQLite file, quiet broken pipes, plain progress lines in logs,
name clashes reported before any computing."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
import time

import pytest

from railval.app.cli import Progress, main


def _run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_internal_error_is_one_line_without_traceback(tmp_path, capsys, monkeypatch):
    from railval.db import catalogue, repo

    def broken(session):
        raise RuntimeError("boom in /srv/secret/path.py")

    monkeypatch.setattr(repo, "list_campaigns", broken)
    # the ordinary path, also once the file exists (the driver-only catalogue would answer)
    monkeypatch.setattr(catalogue, "read_catalogue", lambda url, who: None)
    url = f"sqlite:///{tmp_path / 'x.db'}"
    code, _, err = _run(capsys, "--db", url, "list")
    assert code == 1
    assert err.strip() == ("railval list: error: internal error (RuntimeError); run "
                           "`railval --debug list …` for the details")
    code, _, err = _run(capsys, "--debug", "--db", url, "list")
    assert code == 1 and "Traceback" in err and "boom in /srv/secret/path.py" in err


def test_database_error_shows_no_sql(tmp_path, capsys):
    url = f"sqlite:///{tmp_path / 'missing-folder' / 'x.db'}"
    code, _, err = _run(capsys, "--db", url, "list")
    assert code == 1
    assert "Traceback" not in err and "SELECT" not in err and "[SQL" not in err
    assert err.strip() == ("railval list: error: cannot open the database (unable to open "
                           "database file)")


def test_unknown_campaign_does_not_list_the_others(tmp_path, capsys):
    url = f"sqlite:///{tmp_path / 'x.db'}"
    from tests.factories import write_demo_campaign

    write_demo_campaign(tmp_path / "c", n_sections=1, fmt="parquet", name="secret-project")
    assert _run(capsys, "--db", url, "import", str(tmp_path / "c"))[0] == 0
    code, _, err = _run(capsys, "--db", url, "validate", "nope", "--config", "baseline")
    assert code == 2 and "secret-project" not in err
    assert "campaign 'nope' not found; list the campaigns with `railval list`" in err


def test_sqlite_file_created_private(tmp_path, capsys):
    path = tmp_path / "private.db"
    old = os.umask(0o022)
    try:
        assert _run(capsys, "--db", f"sqlite:///{path}", "init")[0] == 0
    finally:
        os.umask(old)
    for p in [path, *tmp_path.glob("private.db-*")]:
        assert stat.S_IMODE(p.stat().st_mode) == 0o600, p


def test_broken_pipe_is_quiet(tmp_path):
    env = {**os.environ, "RAILVAL_DB": f"sqlite:///{tmp_path / 'x.db'}"}
    proc = subprocess.Popen([sys.executable, "-m", "railval.app", "--help"], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()  # the reader is gone before anything is written (like `| head`)
    err = proc.stderr.read().decode()
    proc.wait(60)
    assert "Traceback" not in err and "BrokenPipeError" not in err, err


def test_broken_pipe_of_a_verb_is_quiet(tmp_path):
    env = {**os.environ, "RAILVAL_DB": f"sqlite:///{tmp_path / 'x.db'}"}
    proc = subprocess.Popen([sys.executable, "-m", "railval.app", "list"], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()
    err = proc.stderr.read().decode()
    proc.wait(60)
    assert "Traceback" not in err and "BrokenPipeError" not in err, err


def test_progress_without_terminal_writes_plain_lines():
    import io

    stream = io.StringIO()
    bar = Progress(interval_s=3600, stream=stream)
    for k in range(1, 101):
        bar("simulate", 0.9 * k / 100, {"done": k, "total": 100})
    bar("store", 0.95, {})
    bar("done", 1.0, {})
    text = stream.getvalue()
    assert "\r" not in text
    assert text.splitlines() == ["[  0.9 %] simulate 1/100", "[ 95.0 %] store", "[100.0 %] done"]


def test_synth_progress_in_a_log_has_no_carriage_returns(tmp_path):
    env = {**os.environ, "RAILVAL_DB": f"sqlite:///{tmp_path / 'x.db'}"}
    subprocess.run([sys.executable, "-m", "railval.app", "init"], env=env, check=True,
                   capture_output=True)
    res = subprocess.run([sys.executable, "-m", "railval.app", "synth", "--name", "s1"],
                         env=env, capture_output=True, text=True, timeout=600, check=False)
    assert res.returncode == 0, res.stderr
    assert "\r" not in res.stderr and res.stderr.count("\n") < 40
    # the same name again: refused at once, before minutes of simulation
    t = time.perf_counter()
    res = subprocess.run([sys.executable, "-m", "railval.app", "synth", "--name", "s1"],
                         env=env, capture_output=True, text=True, timeout=600, check=False)
    elapsed = time.perf_counter() - t
    assert res.returncode == 2
    assert res.stderr.strip() == ("railval synth: error: field name: a campaign named 's1' "
                                  "already exists in the database")
    assert elapsed < 15


@pytest.mark.parametrize("argv,match", [
    (["synth", "--name", "<img src=x>"], "campaign name '<img src=x>' holds the character '<'"),
    (["simulate", "demo", "--config", "a\"b"], "configuration name 'a\"b' holds the character"),
])
def test_unsafe_names_refused_by_the_cli(tmp_path, capsys, argv, match):
    url = f"sqlite:///{tmp_path / 'x.db'}"
    from tests.factories import write_demo_campaign

    write_demo_campaign(tmp_path / "c", n_sections=1, fmt="parquet")
    assert _run(capsys, "--db", url, "import", str(tmp_path / "c"))[0] == 0
    code, _, err = _run(capsys, "--db", url, *argv)
    assert code == 2 and match in err


def test_duplicate_configuration_names_replace_option(tmp_path, capsys):
    url = f"sqlite:///{tmp_path / 'x.db'}"
    from tests.factories import write_demo_campaign

    write_demo_campaign(tmp_path / "c", n_sections=1, fmt="parquet")
    assert _run(capsys, "--db", url, "import", str(tmp_path / "c"))[0] == 0
    t = time.perf_counter()
    code, _, err = _run(capsys, "--db", url, "simulate", "demo", "--config", "baseline")
    assert code == 2 and time.perf_counter() - t < 10
    assert ("configuration 'baseline' already exists in campaign 'demo'; choose another name, "
            "or overwrite it with --replace") in err
    assert "replace=True" not in err

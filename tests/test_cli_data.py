"""railval init / import / export / list / bench on both backends."""

from __future__ import annotations

import json

import pytest

from railval.app.cli import main

from tests.factories import write_demo_campaign


def _run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_init_import_list_export(db_url, tmp_path, capsys):
    code, out, _ = _run(capsys, "--db", db_url, "init", "--json")
    assert code == 0 and json.loads(out)["previous_revision"] is None
    code, out, _ = _run(capsys, "--db", db_url, "init")
    assert code == 0 and "already at revision" in out

    write_demo_campaign(tmp_path / "c", n_sections=4, fmt="csv", n_configs=2)
    code, out, err = _run(capsys, "--db", db_url, "import", str(tmp_path / "c"), "--json")
    assert "reading" in err and "12/12" in err  # tqdm progress on stderr, stdout stays JSON
    doc = json.loads(out)
    assert code == 0 and doc["name"] == "demo" and doc["n_sections"] == 4
    assert doc["zones"] == {"1": 1, "2": 1, "3": 1, "4": 1}
    assert doc["n_signals"] == 4 * 3 * 12
    assert [c["parent"] for c in doc["configurations"]] == [None, "baseline"]

    code, out, _ = _run(capsys, "--db", db_url, "list", "--json")
    listed = json.loads(out)["campaigns"]
    assert [c["name"] for c in listed] == ["demo"]
    assert [s["zone"] for s in listed[0]["sections"]] == [1, 2, 3, 4]
    code, out, _ = _run(capsys, "--db", db_url, "list")
    assert "demo (id" in out and "variant1 ← baseline" in out

    code, out, _ = _run(capsys, "--db", db_url, "export", "demo", str(tmp_path / "e"),
                        "--format", "csv")
    assert code == 0 and (tmp_path / "e" / "campaign.json").is_file()
    assert (tmp_path / "e" / "sim" / "variant1" / "S04.csv").is_file()

    # errors: exit status 2 and a message naming the problem, nothing written
    code, _, err = _run(capsys, "--db", db_url, "import", str(tmp_path / "e"))
    assert code == 2 and "campaign named 'demo' already exists" in err
    code, _, err = _run(capsys, "--db", db_url, "export", "nope", str(tmp_path / "x"))
    assert code == 2 and "'nope' not found; list the campaigns with `railval list`" in err
    assert "demo" not in err


def test_import_reports_bad_folder(tmp_path, capsys):
    url = f"sqlite:///{tmp_path / 'x.db'}"
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "campaign.json").write_text("{not json")
    code, _, err = _run(capsys, "--db", url, "import", str(tmp_path / "bad"))
    assert code == 2 and "file campaign.json" in err and "malformed JSON" in err
    code, out, _ = _run(capsys, "--db", url, "list", "--json")
    assert json.loads(out)["campaigns"] == []


def test_export_needs_an_initialised_database(tmp_path, capsys):
    code, _, err = _run(capsys, "--db", f"sqlite:///{tmp_path / 'empty.db'}", "export", "x",
                        str(tmp_path / "o"))
    assert code == 2 and "railval init" in err


def test_bench_lists_and_runs(tmp_path, capsys, monkeypatch):
    import types

    from railval.app.cli import cmd_bench

    fake = types.ModuleType("railval.app.bench.bench_fake")
    fake.__doc__ = "A fake benchmark."

    def add_arguments(parser):
        parser.add_argument("--n", type=int, default=3)

    fake.add_arguments = add_arguments
    fake.run = lambda args: {"n": args.n, "speed": {"MB_per_s": 12.5}}
    monkeypatch.setattr(cmd_bench, "available", lambda: {"fake": "bench_fake"})
    monkeypatch.setitem(__import__("sys").modules, "railval.app.bench.bench_fake", fake)
    code, out, _ = _run(capsys, "bench")
    assert code == 0 and "fake" in out and "A fake benchmark." in out
    code, out, _ = _run(capsys, "bench", "fake", "--n", "7")
    assert code == 0 and "speed.MB_per_s" in out and "12.5" in out and "7" in out
    code, out, _ = _run(capsys, "bench", "fake", "--json")
    assert json.loads(out) == {"benchmark": "fake", "figures": {"n": 3, "speed": {"MB_per_s": 12.5}}}
    code, _, err = _run(capsys, "bench", "nope")
    assert code == 2 and "benchmark 'nope' not found" in err


@pytest.mark.parametrize("verb", ["init", "import", "export", "list", "bench"])
def test_verbs_have_help(verb, capsys):
    with pytest.raises(SystemExit) as info:
        main([verb, "--help"])
    assert info.value.code == 0
    assert "usage: railval" in capsys.readouterr().out

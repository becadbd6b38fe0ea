"""A newcomer's clone: the README names `railval init`, and the secrets railval writes beside
its SQLite database never show as untracked files (.gitignore).

Real run: `railval init`, `railval import` (creates the seal key), `railval audit key` (creates the signing key), `railval audit seal`
(a signed head in the witness file) and `railval audit rotate-key` (the old key kept beside
the new one) in a fresh git repository holding the project's .gitignore; `git status` then
lists the .gitignore alone. The file names of the database's seal key and signing key come
from the functions that choose them (db/integrity.py).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from railval.db import integrity

from tests.factories import write_demo_campaign

ROOT = Path(__file__).resolve().parents[1]


def _git(cwd: Path, *args: str) -> str:
    return subprocess.run(["git", *args], cwd=cwd, check=True, capture_output=True,
                          text=True).stdout


def test_readme_verb_list_names_init():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    verbs = text.split("## What it does", 1)[1].split("```", 2)[1]
    assert re.search(r"^railval init\s+# create or upgrade the database schema", verbs, re.M)
    assert verbs.index("railval init") < verbs.index("railval synth")


def test_secrets_beside_the_database_are_ignored(tmp_path):
    repo = tmp_path / "clone"
    repo.mkdir()
    _git(repo, "init", "-q")
    shutil.copy(ROOT / ".gitignore", repo / ".gitignore")
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAILVAL_")}
    env |= {"XDG_CONFIG_HOME": str(tmp_path / "config"), "RAILVAL_TRUST_DIR": str(repo)}
    url = f"sqlite:///{repo / 'railval.db'}"
    write_demo_campaign(tmp_path / "camp", n_sections=1, fs=50.0, name="demo")
    for verb in (["init"], ["import", str(tmp_path / "camp")], ["audit", "key"],
                 ["audit", "seal"], ["audit", "rotate-key"]):
        run = subprocess.run([sys.executable, "-m", "railval.app", "--db", url, *verb], cwd=repo,
                             env=env, capture_output=True, text=True, timeout=300)
        assert run.returncode == 0, (verb, run.stderr)
    written = sorted(p.name for p in repo.iterdir() if p.name not in (".git", ".gitignore"))
    assert integrity.secret_path(url).name in written
    assert integrity.signing_key_path(url).name in written
    assert any(".signing-key.pem.old-" in n for n in written), written  # the rotated key
    assert _git(repo, "status", "--porcelain", "--untracked-files=all").splitlines() == [
        "?? .gitignore"], written
    for name in ("cookie.secret", "railval.db.signing-key.witness.jsonl",
                 "railval.db.signing-key.pem.retired", "other.db.key"):
        assert _git(repo, "check-ignore", "--no-index", name).strip() == name

"""Installing railval prints no warnings from the project's own configuration (a new user
reads every line of ``pip install -v -e .``): no deprecated ``project.license`` table, and no
generic editable-install notice — tools/build_backend.py says why those notices do not apply,
and these tests keep the reasons true."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NOTICES = ("Editable installation", "careful with folders", "Editable install will be performed")


def _copy_repo(tmp_path: Path) -> Path:
    dst = tmp_path / "repo"
    shutil.copytree(ROOT, dst, ignore=shutil.ignore_patterns(
        ".git", ".venv", "*.egg-info", "__pycache__", "build", "dist", "*.db", "test-artifacts",
        "bench-data", ".pytest_cache", ".hypothesis"))
    return dst


def _build_editable(repo: Path, backend: str) -> str:
    """Run a backend's ``build_editable`` hook as pip does (separate process, repo as cwd)
    and return everything it printed."""
    code = (f"import sys; sys.path.insert(0, 'tools'); import {backend} as b; "
            "print(b.build_editable('dist'))")
    run = subprocess.run([sys.executable, "-W", "default", "-c", code], cwd=repo,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    return run.stdout + run.stderr


def test_editable_build_prints_no_generic_notice_and_no_warning(tmp_path):
    repo = _copy_repo(tmp_path)
    out = _build_editable(repo, "build_backend")
    assert not [n for n in NOTICES if n in out], out[-3000:]
    warn_lines = [ln for ln in out.splitlines() if "warning" in ln.lower() or "deprecat" in ln.lower()]
    assert not warn_lines, warn_lines
    wheel = repo / "dist" / out.strip().splitlines()[-1]
    assert wheel.is_file() and wheel.name.startswith("railval-")


def test_the_notice_check_would_see_setuptools_own_notice(tmp_path):
    """The same build through setuptools' plain backend prints the notice: the check above
    can fail."""
    repo = _copy_repo(tmp_path)
    out = _build_editable(repo, "setuptools.build_meta")
    assert any(n in out for n in NOTICES), out[-2000:]


def test_no_folder_shadows_the_package_name():
    """The silenced notice warns about a working-directory folder named like the package."""
    assert not (ROOT / "railval").exists()
    backend = (ROOT / "pyproject.toml").read_text()
    assert 'build-backend = "build_backend"' in backend and 'backend-path = ["tools"]' in backend


def test_package_data_is_read_through_the_editable_mapping():
    """The other silenced notice says package-data options may have no effect: the schemas,
    migrations and page styles are found through the installed package names."""
    import importlib.resources as res

    assert res.files("railval.db.schema").joinpath("campaign.schema.json").is_file()
    assert res.files("railval.db.migrations").joinpath("env.py").is_file()

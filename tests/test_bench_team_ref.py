"""``railval bench team --ref COMMIT`` refuses a commit whose database schema is not the
working tree's: both codes serve one database (app/bench/bench_team.py ``check_same_schema``)."""

from __future__ import annotations

import base64
import shutil
import subprocess
from pathlib import Path

import pytest

from railval.app.bench.bench_team import MIGRATIONS, _export, check_same_schema
from railval.app.bench.topology import NO_FONT_HOSTS, REPO, browser_trust, self_signed
from railval.core.errors import InvalidParameter
from railval.db.catalogue import head_revision


def _copy_scripts(dest: Path) -> Path:
    shutil.copytree(REPO / MIGRATIONS, dest / MIGRATIONS, ignore=shutil.ignore_patterns("__pycache__"))
    return dest / MIGRATIONS


def test_the_same_scripts_pass(tmp_path):
    _copy_scripts(tmp_path)
    check_same_schema("same", tmp_path)  # no error


def test_the_exported_head_commit_is_accepted_and_laid_out_as_the_package(tmp_path):
    pkg = Path(_export("HEAD", tmp_path))
    assert (pkg / "railval" / "db" / "catalogue.py").is_file()
    assert head_revision(tmp_path / "ref-src" / MIGRATIONS) == head_revision()


def test_a_changed_script_is_refused_with_its_name_and_both_heads(tmp_path):
    versions = _copy_scripts(tmp_path)
    last = sorted(versions.glob("0*.py"))[-1]
    last.write_text(last.read_text("utf-8") + "\n# a column more\n", "utf-8")
    with pytest.raises(InvalidParameter) as e:
        check_same_schema("abc123", tmp_path)
    msg = str(e.value)
    assert "--ref abc123" in msg and last.name in msg and head_revision() in msg


def test_a_missing_newest_migration_is_refused(tmp_path):
    """A commit from before the newest migration (its head is the one before)."""
    versions = _copy_scripts(tmp_path)
    newest = sorted(versions.glob("0*.py"))[-1]
    newest.unlink()
    with pytest.raises(InvalidParameter) as e:
        check_same_schema("old", tmp_path)
    msg = str(e.value)
    assert newest.name in msg
    assert f"head {head_revision(versions)} against {head_revision()}" in msg
    assert head_revision(versions) != head_revision()


def test_an_extra_script_is_refused(tmp_path):
    versions = _copy_scripts(tmp_path)
    (versions / "0099_planted.py").write_text('revision = "0099"\ndown_revision = "x"\n', "utf-8")
    with pytest.raises(InvalidParameter, match="0099_planted.py"):
        check_same_schema("new", tmp_path)


def test_browser_trust_names_the_certificates_key_as_openssl_hashes_it(tmp_path):
    """The key hash Chromium is given equals base64(SHA-256(SubjectPublicKeyInfo, DER)) computed
    by openssl alone from the certificate."""
    cert, _key = self_signed(tmp_path)
    pub = subprocess.run(["openssl", "x509", "-in", str(cert), "-noout", "-pubkey"], check=True,
                         capture_output=True).stdout
    der = subprocess.run(["openssl", "pkey", "-pubin", "-outform", "DER"], input=pub, check=True,
                         capture_output=True).stdout
    digest = subprocess.run(["openssl", "dgst", "-sha256", "-binary"], input=der, check=True,
                            capture_output=True).stdout
    flags = browser_trust(cert)
    assert flags == [f"--ignore-certificate-errors-spki-list={base64.b64encode(digest).decode()}", NO_FONT_HOSTS]

"""A killed railval process leaves no worker processes and no temporary folders behind."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest


def _children() -> dict[int, list[int]]:
    tree: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        ppid = int(stat.rsplit(")", 1)[1].split()[1])
        tree.setdefault(ppid, []).append(int(entry.name))
    return tree


def _descendants(pid: int) -> set[int]:
    tree, out, todo = _children(), set(), [pid]
    while todo:
        for child in tree.get(todo.pop(), []):
            if child not in out:
                out.add(child)
                todo.append(child)
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


SCRIPT = {
    "batch": """
        import time
        from railval.app.services.batch import BatchExecutor
        with BatchExecutor(workers=2) as ex:
            ex.map(time.sleep, [120, 120])
    """,
    "simulation-pool": """
        import time
        from railval.core.sim import model
        pool = model._pool(2)
        futures = [pool.submit(time.sleep, 120) for _ in range(2)]
        futures[0].result()
    """,
}


@pytest.mark.parametrize("kind", sorted(SCRIPT))
def test_workers_end_with_a_killed_parent(kind):
    proc = subprocess.Popen([sys.executable, "-c", textwrap.dedent(SCRIPT[kind])])
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            family = _descendants(proc.pid)
            if len(family) >= 2:
                time.sleep(1.0)  # let the pool start both workers
                family = _descendants(proc.pid)
                break
            time.sleep(0.2)
        assert len(family) >= 2, f"pool did not start: {family}"
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline and any(_alive(p) for p in family):
        time.sleep(0.2)
    left = sorted(p for p in family if _alive(p))
    for p in left:  # clean up before failing
        os.kill(p, signal.SIGKILL)
    assert not left, f"processes left running after the parent was killed: {left}"


def test_stale_synth_folders_removed_at_next_start(tmp_path):
    from railval.app.services import synth

    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = tmp_path / f"{synth.TEMP_PREFIX}{dead.pid}-abc"
    (stale / "measured").mkdir(parents=True)
    (stale / "measured" / "S01.parquet").write_bytes(b"x" * 1000)
    mine = tmp_path / f"{synth.TEMP_PREFIX}{os.getpid()}-def"
    mine.mkdir()
    other = tmp_path / "unrelated"
    other.mkdir()
    assert synth.remove_stale_folders(tmp_path) == [stale]
    assert not stale.exists() and mine.exists() and other.exists()


@pytest.mark.slow
def test_killed_synth_leaves_no_folder_after_next_run(tmp_path):
    """SIGKILL a `railval synth` while its folder exists; the next synth removes it."""
    env = {**os.environ, "TMPDIR": str(tmp_path), "RAILVAL_DB": f"sqlite:///{tmp_path / 's.db'}"}
    subprocess.run([sys.executable, "-m", "railval.app", "init"], env=env, check=True,
                   capture_output=True)
    proc = subprocess.Popen([sys.executable, "-m", "railval.app", "synth", "--name", "k1"],
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 240
    folders: list[Path] = []
    while time.monotonic() < deadline and not folders:
        folders = list(tmp_path.glob("railval-synth-*"))
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert folders, "synth never created its folder"
    assert any(f.exists() for f in folders)
    from railval.app.services import synth

    assert synth.remove_stale_folders(tmp_path) == folders
    assert not list(tmp_path.glob("railval-synth-*"))

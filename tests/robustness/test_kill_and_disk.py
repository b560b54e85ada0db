"""Crashes and a full disk, through the real command in a subprocess.

* kill -9 at 20+ random moments of one session, each followed by the same command: no finished press is ever lost,
  rewritten or duplicated, and the last run completes the session;
* a file-size limit (RLIMIT_FSIZE, SIGXFSZ ignored, so writes fail with EFBIG as on a full disk): the command stops
  with one line, the session file stays readable, and the same command resumes once the limit is lifted; a limit
  larger than one press never stops a session (no file grows with the session).
"""

from __future__ import annotations

import resource
import signal
import subprocess
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from tests.helpers import console_script
from unitac_rig.storage.recorder import session_path


def _collect_cmd(data: Path, angles: int, obj: str = "hex_pla") -> list[str]:
    return [
        console_script(),
        "collect",
        "--object",
        obj,
        "--sensor",
        "uskin",
        "--data",
        str(data),
        "--angles",
        str(angles),
        "--no-live",
    ]


def _journal_entries(journal: Path) -> dict[str, tuple[int, int]]:
    """Finished (durable) presses in the journal: press id -> (inode, mtime ns) of its file."""
    out = {}
    for path in journal.glob("*.h5"):
        try:
            st = path.stat()
        except FileNotFoundError:
            continue
        out[path.stem] = (st.st_ino, st.st_mtime_ns)
    return out


def _session_statuses(path: Path) -> dict[str, str]:
    with h5py.File(path, "r") as f:
        return {pid: str(g.attrs["status"]) for pid, g in f["presses"].items() if g.attrs.get("write_complete")}


@pytest.mark.slow
def test_twenty_kills_at_random_moments_lose_and_duplicate_nothing(tmp_path: Path) -> None:
    angles, kills = 91, 22  # the paper's full arc
    rng = np.random.default_rng(2025)
    cmd = _collect_cmd(tmp_path, angles)
    journal = tmp_path / ".journal" / "hex_pla__uskin"
    seen: dict[str, tuple[int, int]] = {}  # every finished press ever observed, with the identity of its file
    header = journal / "_session.json"
    killed = 0
    while killed < kills:
        before = len(_journal_entries(journal))
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            # Timed from what the process has done, not from its start, so a slow or loaded box still sees progress:
            # during start-up; some time into the session (tare, presses, transit moves); or just after a press
            # became durable (while it is copied into the session file, or the next press starts).
            moment = int(rng.integers(3))
            if moment == 0:
                time.sleep(float(rng.uniform(0.05, 0.6)))
            else:
                deadline = time.monotonic() + 60
                while (
                    proc.poll() is None
                    and time.monotonic() < deadline
                    and not (header.exists() if moment == 1 else len(_journal_entries(journal)) > before)
                ):
                    time.sleep(0.005)
                time.sleep(float(rng.uniform(0.0, 0.8 if moment == 1 else 0.15)))
            finished = proc.poll() is not None
            proc.send_signal(signal.SIGKILL)
        finally:
            proc.wait()
        assert not finished, "the session finished before the kill: use more angles"
        killed += 1
        now = _journal_entries(journal)
        for pid, identity in seen.items():
            assert now.get(pid) == identity, f"kill {killed}: finished press {pid} was lost or written again"
        seen.update(now)
    assert 5 <= len(seen) < angles, len(seen)  # the kills interrupted a session that was making progress
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    final = _journal_entries(journal)
    assert all(final[pid] == identity for pid, identity in seen.items())  # never redone after any kill
    statuses = _session_statuses(session_path(tmp_path, "hex_pla", "uskin"))
    assert len(statuses) == len(final) == angles
    assert set(statuses.values()) == {"complete"}


def _limit_file_size(max_bytes: int):  # type: ignore[no-untyped-def]
    def apply() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # writes past the limit fail with EFBIG instead of killing
        resource.setrlimit(resource.RLIMIT_FSIZE, (max_bytes, max_bytes))

    return apply


def test_a_full_disk_stops_with_one_line_keeps_the_file_readable_and_resumes(tmp_path: Path) -> None:
    presses = 16  # ~0.1 MB each since the faster press (issue 27): not even the first press fits 150 kB
    cmd = _collect_cmd(tmp_path, presses)
    full = subprocess.run(cmd, capture_output=True, text=True, timeout=120, preexec_fn=_limit_file_size(150_000))
    assert full.returncode == 1, full.stderr
    lines = full.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: no room to record"), full.stderr
    assert "File too large" in lines[0] and "rerun the same command" in lines[0]
    path = session_path(tmp_path, "hex_pla", "uskin")
    before = _session_statuses(path)  # readable, and only whole presses in it
    assert before == {} and _journal_entries(tmp_path / ".journal" / "hex_pla__uskin") == {}
    resumed = subprocess.run(cmd, capture_output=True, text=True, timeout=240)
    assert resumed.returncode == 0, resumed.stderr
    after = _session_statuses(path)
    assert len(after) == presses and set(after.values()) == {"complete"}
    assert set(before) <= set(after)


def test_no_file_grows_with_the_session(tmp_path: Path) -> None:
    """Each press has its own file and the session file holds only links: a per-file size limit of 900 kB, which
    the single-file layout outgrew after a few presses, never stops a 16-press session."""
    presses = 16
    done = subprocess.run(
        _collect_cmd(tmp_path, presses),
        capture_output=True,
        text=True,
        timeout=240,
        preexec_fn=_limit_file_size(900_000),
    )
    assert done.returncode == 0, done.stderr
    statuses = _session_statuses(session_path(tmp_path, "hex_pla", "uskin"))
    assert len(statuses) == presses and set(statuses.values()) == {"complete"}

"""Readers never disturb the writer: inspect, extract's and train's reader paths, plain h5py handles (even one held
open for the whole session) and ``inspect --watch`` run against a collection, which still completes every press.
One process writes a session at a time (the lease); a second one is told who holds it."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from tests.helpers import cli
from tests.robustness.robustness_helpers import one_error_line, write_synthetic_sessions
from unitac_rig.errors import DataError
from unitac_rig.storage.reader import list_sessions, load_matched_set, load_matched_sets, press_summaries, read_presses
from unitac_rig.storage.recorder import SessionWriter, journal_dir, session_path

ATTRS = {"object": "circle_pla", "sensor": "uskin", "simulated": True}

# another process that opens the session for writing and keeps it until its stdin closes
HOLD_WRITER = (
    "import sys; from pathlib import Path; from unitac_rig.storage.recorder import SessionWriter; "
    "w = SessionWriter(Path(sys.argv[1]), 'circle_pla', 'uskin', {'object': 'circle_pla', 'sensor': 'uskin'}); "
    "print('holding', flush=True); sys.stdin.read()"
)
PROBE = (
    "import json, sys; from unitac_rig.storage.lease import lease_holder; print(json.dumps(lease_holder(sys.argv[1])))"
)


def _probe_from_another_process(journal: Path) -> dict | None:
    out = subprocess.run([sys.executable, "-c", PROBE, str(journal)], capture_output=True, text=True, check=True)
    return json.loads(out.stdout)  # type: ignore[no-any-return]


def test_a_reader_holding_the_file_open_never_blocks_the_writer(tmp_path: Path) -> None:
    src = tmp_path / "src"
    write_synthetic_sessions(src, ("circle_pla",))
    records = read_presses(session_path(src, "circle_pla", "uskin"))
    writer = SessionWriter(tmp_path / "data", "circle_pla", "uskin", ATTRS)
    writer.write_press(records[0])
    path = session_path(tmp_path / "data", "circle_pla", "uskin")
    held = h5py.File(path, "r")  # a notebook that opened the session and never closed it
    try:
        for count, record in enumerate(records[1:], start=2):
            writer.write_press(record)
            with h5py.File(path, "r") as fresh:  # a reader opening now sees every finished press
                assert len(fresh["presses"]) == count
        # the held handle keeps its own complete snapshot, readable to the end
        assert list(held["presses"]) == [records[0].press_id]
        frames = held["presses"][records[0].press_id]["extraction/values"][()]
        with h5py.File(session_path(src, "circle_pla", "uskin"), "r") as original:
            assert np.array_equal(frames, original["presses"][records[0].press_id]["extraction/values"][()])
    finally:
        held.close()
        writer.close()
    assert len(load_matched_set(path)) == len(load_matched_set(session_path(src, "circle_pla", "uskin")))


def test_one_writer_per_session_and_extract_waits_for_the_collection(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    write_synthetic_sessions(tmp_path, ("circle_pla",))
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLD_WRITER, str(tmp_path)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "holding"
        with pytest.raises(DataError, match=rf"being written by another process \(pid {holder.pid} "):
            SessionWriter(tmp_path, "circle_pla", "uskin", ATTRS)
        before = session_path(tmp_path, "circle_pla", "uskin").stat().st_mtime_ns
        assert cli(["extract", str(tmp_path)]) == 1
        line = one_error_line(capsys)
        assert "being written by another process" in line and "rerun extract when" in line
        assert session_path(tmp_path, "circle_pla", "uskin").stat().st_mtime_ns == before
        assert cli(["inspect", str(tmp_path), "--json"]) == 0
        writers = {s["sensor"]: s["writer"] for s in json.loads(capsys.readouterr().out)["sessions"]}
        assert writers["uskin"]["pid"] == holder.pid and writers["papillarray"] is None
    finally:
        holder.communicate(timeout=30)  # closes its stdin: the holder exits and the kernel drops its lock
    assert cli(["extract", str(tmp_path)]) == 0
    SessionWriter(tmp_path, "circle_pla", "uskin", ATTRS).close()


def test_a_second_writer_in_the_same_process_takes_the_lease_over(tmp_path: Path) -> None:
    write_synthetic_sessions(tmp_path, ("circle_pla",))
    journal = journal_dir(tmp_path, "circle_pla", "uskin")
    first = SessionWriter(tmp_path, "circle_pla", "uskin", ATTRS)
    second = SessionWriter(tmp_path, "circle_pla", "uskin", ATTRS)  # e.g. a resumed session in the same process
    first.close()  # the stale writer's close must not release the lease the second one now holds
    assert _probe_from_another_process(journal)["pid"] == os.getpid()
    second.close()
    assert _probe_from_another_process(journal) is None


def _has_a_press(path: Path) -> bool:
    if not path.exists():
        return False
    with h5py.File(path, "r") as f:
        return len(f["presses"]) > 0


@pytest.mark.slow
def test_readers_in_a_loop_never_disturb_a_91_press_collection(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = tmp_path / "data"
    path = session_path(data, "hex_tpu", "papillarray")
    module = [sys.executable, "-m", "unitac_rig"]
    collect = subprocess.Popen(
        [*module, "collect", "--object", "hex_tpu", "--sensor", "papillarray", "--data", str(data), "--no-live"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    watch = subprocess.Popen(
        [*module, "inspect", str(data), "--watch", "--interval", "1", "--json"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    held: h5py.File | None = None
    seen: list[int] = []  # presses each inspect saw
    failures: list[str] = []
    extract_refusal = ""
    try:
        while not _has_a_press(path) and collect.poll() is None:
            time.sleep(0.1)
        held = h5py.File(path, "r")  # a notebook that opens the file early and never closes it
        while collect.poll() is None:
            try:
                assert cli(["inspect", str(data), "--json"]) == 0, capsys.readouterr().err
                (session,) = json.loads(capsys.readouterr().out)["sessions"]
                seen.append(session["presses_complete"])
                for info in list_sessions(data):  # extract's reader path
                    press_summaries(info.path)
                if len(seen) % 4 == 0:
                    load_matched_sets(data)  # train's reader path (every 4th round: it reads every press)
                with h5py.File(path, "r") as f:  # a plain h5py reader
                    last = sorted(f["presses"])[-1]
                    assert f["presses"][last]["tactile/values"][()].ndim == 3
                first = sorted(held["presses"])[0]
                assert held["presses"][first]["robot/t_s"][()].size > 0
                if len(seen) == 3:  # extract would rewrite the file: it must refuse, and the collection go on
                    assert cli(["extract", str(data)]) == 1
                    extract_refusal = one_error_line(capsys)
            except Exception as exc:  # every failed read is reported at the end
                failures.append(f"read {len(seen)}: {type(exc).__name__}: {exc}")
            time.sleep(0.5)  # a reader per half second: the box is shared, the collection must keep its pace
        out, err = collect.communicate(timeout=60)
    finally:
        if held is not None:
            held.close()
        if collect.poll() is None:
            collect.kill()
            collect.wait()
        watch.send_signal(signal.SIGINT)
        watch_out, watch_err = watch.communicate(timeout=60)
    assert collect.returncode == 0, err
    assert "91/91 presses finished" in " ".join(out.split())
    assert failures == []
    assert "being written by another process" in extract_refusal
    # the reads really overlapped the writes: they saw the session grow
    assert len(seen) >= 5 and any(0 < n < 91 for n in seen), seen
    assert seen == sorted(seen)
    with h5py.File(path, "r") as f:
        statuses = [str(g.attrs["status"]) for g in f["presses"].values()]
    assert len(statuses) == 91 and set(statuses) == {"complete"}
    assert not list(data.glob(".*.tmp"))  # no private copy left behind
    # inspect --watch refreshed all along (one JSON document per refresh) and stopped cleanly on Ctrl-C
    assert watch.returncode == 0, watch_err
    refreshes = [json.loads(line) for line in watch_out.splitlines() if line.strip()]
    counts = [r["sessions"][0]["presses_complete"] for r in refreshes if r.get("sessions")]
    assert any(0 < n < 91 for n in counts) and counts == sorted(counts), counts
    assert any(r["sessions"][0]["writer"] for r in refreshes if r.get("sessions"))
    assert cli(["extract", str(data)]) == 0  # the lease went with the collecting process

"""`unitac-rig view ... --save out.rrd`: what the viewer logged, read back from the recording file with Rerun's own
reader: every frame as a taxel tensor of the sensor's grid, the wrist force and pad pose at every arm sample, one
matched-target point per force-matched frame, the values the session holds; and a live stream of the simulated rig."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.helpers import cli, run_console
from unitac_rig.storage.reader import read_presses

rr = pytest.importorskip("rerun")


def _rows(rrd: Path) -> dict[str, list]:
    """entity path -> its chunks' record batches."""
    from rerun.chunk import RrdReader

    out: dict[str, list] = {}
    for chunk in RrdReader(rrd).stream():
        out.setdefault(str(chunk.entity_path), []).append(chunk.to_record_batch())
    return out


def _count(batches: list) -> int:
    return sum(b.num_rows for b in batches)


def _column(batches: list, suffix: str) -> list:
    values: list = []
    for batch in batches:
        name = next(n for n in batch.schema.names if n.endswith(suffix))
        values += batch.column(name).to_pylist()
    return values


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A simulated-rig session at 3 angles (real streams: a tare, arm poses, force-matched frames)."""
    data = tmp_path_factory.mktemp("view") / "data"
    assert cli(["collect", "--object", "circle_pla", "--data", str(data), "--angles", "3", "--no-live"]) == 0
    return next(data.glob("circle_pla__uskin*.h5"))


def test_view_save_logs_frames_force_pose_and_matched_targets(session: Path, tmp_path: Path) -> None:
    rrd = tmp_path / "session.rrd"
    assert cli(["view", str(session), "--save", str(rrd)]) == 0
    logged = _rows(rrd)
    presses = read_presses(session)
    frames = sum(p.tactile_t_s.size for p in presses)
    arm = sum(p.robot_t_s.size for p in presses)
    matched = sum(int((~np.asarray(p.extraction.miss, bool)).sum()) for p in presses if p.extraction is not None)
    assert _count(logged["/tactile/uskin/frame"]) == frames and _count(logged["/tactile/uskin/z"]) == frames
    assert _count(logged["/arm/force/fz"]) == _count(logged["/arm/pad"]) == arm
    assert _count(logged["/tactile/uskin/matched"]) == matched > 0
    assert _count(logged["/press"]) == len(presses)
    # a value: the matched targets are the extraction's target forces
    extractions = [p.extraction for p in presses if p.extraction is not None]
    targets = sorted(float(t) for ex in extractions for t, miss in zip(ex.targets_n, ex.miss, strict=True) if not miss)
    got = sorted(float(v[0]) for v in _column(logged["/tactile/uskin/matched"], "scalars"))
    assert got == pytest.approx(targets)
    # a frame: the first press's first frame, tare-subtracted, on the 4 x 6 grid
    first = presses[0]
    expected = (np.asarray(first.tactile_values[0], np.float32) - np.asarray(first.tare_baseline, np.float32)).reshape(
        -1
    )
    tensors = _column(logged["/tactile/uskin/frame"], "data")
    flat = [np.asarray(t[0]["buffer"], np.float32) if isinstance(t[0], dict) else np.asarray(t[0]) for t in tensors]
    assert any(np.array_equal(f, expected) for f in flat)


def test_view_refuses_without_a_target_or_stream(tmp_path: Path) -> None:
    assert cli(["view"]) == 2
    assert cli(["view", str(tmp_path), "--save", str(tmp_path / "x.rrd")]) == 2  # no session in it


def test_view_stream_simulated_logs_live_frames(tmp_path: Path) -> None:
    rrd = tmp_path / "live.rrd"
    assert cli(["view", "--stream", "--simulated", "--frames", "40", "--tare-frames", "10", "--save", str(rrd)]) == 0
    logged = _rows(rrd)
    assert _count(logged["/tactile/papillarray/frame"]) == 40


def test_view_is_in_the_help_at_80_columns() -> None:
    def help_of(*args: str) -> str:
        done = run_console(*args, "--help")
        assert done.returncode == 0, done.stderr
        return done.stdout

    root = help_of()
    group = root[root.index("Look at and share data") :].split("\n\n")[0]
    assert "view" in group
    text = help_of("view")
    assert all(len(line) <= 80 for line in text.splitlines()) and "(default" not in text, text
    for option in ("--stream", "--simulated", "--save PATH", "--frames N"):
        assert option in text
    assert "rosbag2" in help_of("export") and "--push-to-hub REPO" in help_of("export-model")

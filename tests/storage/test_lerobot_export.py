"""``export --format lerobot``: every press an episode of a LeRobotDataset v3 per sensor, with its frames, wrench, pose
and annotations; stats as LeRobot computes them; and the way back gives the pairs of the Parquet export.

The ``lerobot`` test loads the export with the standalone ``lerobot-dataset`` package in its own virtual environment
(``.ci/run`` builds it as ``.venv-lerobot``; elsewhere set ``UNITAC_LEROBOT_PYTHON``): ``pytest -m lerobot``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tests.helpers import cli
from tests.robustness.robustness_helpers import one_error_line
from unitac_rig.learning.data import build_paired_dataset, load_sets
from unitac_rig.storage import cards, lerobot
from unitac_rig.storage.reader import read_presses

SENSORS = ("uskin", "papillarray")
REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """circle_pla pressed at 3 angles by each sensor on the simulated rig (real streams, real matching errors)."""
    root = tmp_path_factory.mktemp("lerobot") / "data"
    for _ in SENSORS:  # the simulated rig mounts the next sensor without a complete session
        assert cli(["collect", "--object", "circle_pla", "--data", str(root), "--angles", "3", "--no-live"]) == 0
    return root


@pytest.fixture(scope="module")
def exported(data: Path) -> Path:
    out = data.parent / "lerobot-export"
    assert cli(["export", str(data), "--format", "lerobot", "--out", str(out)]) == 0
    return out


def _frames(root: Path) -> pd.DataFrame:
    return pd.concat([pd.read_parquet(p) for p in sorted((root / "data").glob("chunk-*/file-*.parquet"))])


def test_the_layout_is_lerobot_v3_one_dataset_per_sensor(exported: Path) -> None:
    for sensor in SENSORS:
        root = exported / sensor
        for rel in ("meta/info.json", "meta/stats.json", "meta/tasks.parquet",
                    "meta/episodes/chunk-000/file-000.parquet", "data/chunk-000/file-000.parquet"):  # fmt: skip
            assert (root / rel).is_file(), rel
        info = json.loads((root / "meta/info.json").read_text())
        assert info["codebase_version"] == "v3.0" and info["fps"] == 100  # the simulated sensors run at 100 Hz
        assert info["data_path"] == "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
        tactile = info["features"][f"observation.tactile.{sensor}"]
        assert tactile["unit"] == {"uskin": "counts", "papillarray": "N"}[sensor]
        assert tactile["shape"] == [{"uskin": 24, "papillarray": 9}[sensor], 3] and tactile["dtype"] == "float32"
        assert info["features"]["observation.wrench"]["unit"] == "N, N m"
        assert info["features"]["observation.tcp_pose"]["names"] == ["x", "y", "z", "rx", "ry", "rz"]
        assert info["features"]["annotation.matched_targets"]["names"][0] == "4.00 N"
        assert info["total_episodes"] == 3 and info["total_frames"] == len(_frames(root))
        tasks = pd.read_parquet(root / "meta/tasks.parquet")  # the way LeRobot reads it: indexed by the task text
        assert list(tasks.index) == ["press the circle_pla object (circle PLA) onto the tactile pad to 10 N"]
        assert list(tasks["task_index"]) == [0]
    assert cli(["verify", str(exported)]) == 0


def test_every_press_is_an_episode_holding_its_frames_wrench_pose_and_annotations(data: Path, exported: Path) -> None:
    for sensor in SENSORS:
        df = _frames(exported / sensor)
        episodes = pd.read_parquet(exported / sensor / "meta/episodes/chunk-000/file-000.parquet")
        presses = read_presses(data / f"circle_pla__{sensor}.h5")
        assert list(episodes["unitac/press_id"]) == [p.press_id for p in presses]
        key = f"observation.tactile.{sensor}"
        for ep, press in zip(episodes.to_dict("records"), presses, strict=True):
            rows = df[df["episode_index"] == ep["episode_index"]]
            assert len(rows) == ep["length"] == len(press.tactile_t_s)
            assert rows["index"].iloc[0] == ep["dataset_from_index"]
            assert rows["index"].iloc[-1] == ep["dataset_to_index"] - 1
            frames = np.stack([np.stack(f) for f in rows[key]])
            tared = press.tactile_values.astype(np.float32) - press.tare_baseline.astype(np.float32)
            assert np.array_equal(frames, tared)
            # one clock: the frame's host time since the first frame, and the nearest arm sample's wrench and pose
            assert np.allclose(rows["timestamp"], press.tactile_t_s - press.tactile_t_s[0], atol=1e-6)
            nearest = np.abs(press.robot_t_s[None, :] - press.tactile_t_s[:, None]).argmin(axis=1)
            assert np.allclose(np.stack(rows["observation.wrench"]), press.robot_force[nearest])
            assert np.allclose(np.stack(rows["observation.tcp_pose"]), press.robot_pose[nearest], atol=1e-6)
            assert np.allclose(rows["observation.arm_dt_s"], press.robot_t_s[nearest] - press.tactile_t_s, atol=1e-6)
            assert set(rows["annotation.object"]) == {"circle_pla"}
            assert set(rows["annotation.angle_deg"]) == {press.angle_deg}
            # the matched-target flags are the press's extraction: target k set on frame_index[k] unless a miss
            flags = np.stack(rows["annotation.matched_targets"])
            ex = press.extraction
            assert ex is not None
            expected = np.zeros_like(flags)
            for k in np.flatnonzero(~ex.miss):
                expected[ex.frame_index[k], k] = True
            assert np.array_equal(flags, expected) and flags.sum() == ex.n_matched
            assert np.array_equal(ep["unitac/tare_baseline"], press.tare_baseline.reshape(-1))
            assert np.array_equal(ep["extraction/frame_index"], ex.frame_index)


def test_stats_are_lerobots_over_every_frame_as_written(exported: Path) -> None:
    for sensor in SENSORS:
        df = _frames(exported / sensor)
        stats = json.loads((exported / sensor / "meta/stats.json").read_text())
        key = f"observation.tactile.{sensor}"
        frames = np.stack([np.stack(f) for f in df[key]])
        channels = frames.reshape(-1, 3).astype(np.float64)  # LeRobot: a (taxels, 3) feature per channel
        assert np.allclose(stats[key]["mean"], channels.mean(axis=0))
        assert np.allclose(stats[key]["std"], channels.std(axis=0))
        assert np.allclose(stats[key]["q50"], np.quantile(channels, 0.5, axis=0))
        assert stats[key]["count"] == [len(df)]
        wrench = np.stack(df["observation.wrench"]).astype(np.float64)
        assert np.allclose(stats["observation.wrench"]["min"], wrench.min(axis=0))
        assert np.allclose(stats["observation.wrench"]["max"], wrench.max(axis=0))
        assert stats["timestamp"]["min"] == [0.0]
        assert set(stats[key]) == {"min", "max", "mean", "std", "count", "q01", "q10", "q50", "q90", "q99"}
        assert "annotation.object" not in stats  # strings have no stats (as in LeRobot)


def test_each_episode_carries_its_own_stats_as_lerobots_writer_does(exported: Path) -> None:
    for sensor in SENSORS:
        df = _frames(exported / sensor)
        episodes = pd.read_parquet(exported / sensor / "meta/episodes/chunk-000/file-000.parquet")
        key = f"observation.tactile.{sensor}"
        for _, ep in episodes.iterrows():
            rows = df[df["episode_index"] == ep["episode_index"]]
            wrench = np.stack(rows["observation.wrench"]).astype(np.float64)
            assert np.allclose(ep["stats/observation.wrench/mean"], wrench.mean(axis=0))
            assert np.allclose(ep["stats/observation.wrench/max"], wrench.max(axis=0))
            channels = np.stack([np.stack(f) for f in rows[key]]).reshape(-1, 3).astype(np.float64)
            assert np.allclose(ep[f"stats/{key}/std"], channels.std(axis=0))
            assert list(ep[f"stats/{key}/count"]) == [len(rows)] == [ep["length"]]
            assert list(ep["stats/frame_index/max"]) == [len(rows) - 1]


def _front_matter(card: str) -> dict[str, object]:
    import yaml

    assert card.startswith("---\n")
    loaded = yaml.safe_load(card[4:].partition("\n---\n")[0])
    assert isinstance(loaded, dict)
    return loaded


def test_each_sensor_folder_is_a_hub_dataset_with_its_own_card(exported: Path) -> None:
    manifest = json.loads((exported / "manifest.json").read_text())
    listed = json.dumps(manifest)
    for sensor in SENSORS:
        card = (exported / sensor / "README.md").read_text()
        meta = _front_matter(card)
        frames = len(_frames(exported / sensor))
        assert meta["license"] == "cc-by-4.0" and meta["task_categories"] == ["robotics"]
        assert meta["size_categories"] == [cards.size_category(frames)] == ["n<1K" if frames < 1000 else "1K<n<10K"]
        assert sensor in meta["tags"] and "LeRobot" in meta["tags"]
        assert "@inproceedings{hou2025unitacnv" in card and "IROS" in card and "2506.19699" in card
        assert f"{sensor}/README.md" in listed  # in the manifest: verify checks it
        assert "torchvision::nms" not in card or "except RuntimeError" in card
        assert "except RuntimeError" in _code(card)  # the loading code survives a CUDA torchvision over a CPU torch
    top = _front_matter((exported / "README.md").read_text())
    assert top["license"] == "cc-by-4.0" and top["size_categories"]
    assert "except RuntimeError" in _code((exported / "README.md").read_text())


def _code(card: str) -> str:
    import re

    blocks = re.findall(r"```python\n(.*?)```", card, flags=re.S)
    assert len(blocks) == 1
    return str(blocks[0])


@pytest.mark.lerobot
def test_each_sensor_cards_code_loads_its_dataset_with_lerobot(exported: Path, tmp_path: Path) -> None:
    python = _lerobot_python()
    if python is None:
        pytest.skip("no lerobot-dataset environment: .ci/run builds .venv-lerobot (or set UNITAC_LEROBOT_PYTHON)")
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "HF_HOME": str(tmp_path / "hf"), "PYTHONNOUSERSITE": "1"}
    env.pop("PYTHONPATH", None)
    for sensor in SENSORS:
        code = _code((exported / sensor / "README.md").read_text()) + "\nprint(len(ds), tuple(frame.shape))\n"
        done = subprocess.run([str(python), "-I", "-c", code], env=env, cwd=exported / sensor, capture_output=True,
                              text=True, timeout=600)  # fmt: skip
        assert done.returncode == 0, done.stderr[-3000:]
        n_taxels = {"uskin": 24, "papillarray": 9}[sensor]
        assert done.stdout.split()[-2:] == [f"({n_taxels},", "3)"]
        assert int(done.stdout.split()[0]) == len(_frames(exported / sensor))


def test_round_trip_gives_the_pairs_of_the_parquet_export(data: Path, exported: Path) -> None:
    parquet = data.parent / "parquet-export"
    assert cli(["export", str(data), "--out", str(parquet)]) == 0
    manifest = json.loads((parquet / "manifest.json").read_text())
    back = build_paired_dataset(lerobot.load_matched_sets(exported))
    assert back.content_hash() == manifest["paired_content_hash"]
    df = pd.read_parquet(parquet / "pairs.parquet")
    assert len(df) == 2 * len(back)
    for sensor in SENSORS:
        rows = df[df["sensor"] == sensor].sort_values("contact")
        assert np.array_equal(np.stack([np.stack(f) for f in rows["frame"]]), back.values[sensor])
        assert np.allclose(rows["force_n"].to_numpy(), back.force_n[sensor])
    # `train --data EXPORT` reads the same sets, under either frame baseline (each episode keeps its start and tare)
    assert build_paired_dataset(load_sets(exported)).content_hash() == manifest["paired_content_hash"]
    recording = build_paired_dataset(load_sets(exported, "recording"))
    assert recording.content_hash() == build_paired_dataset(load_sets(data, "recording")).content_hash()
    assert recording.content_hash() != manifest["paired_content_hash"]  # the twin drifts between presses


def test_exporting_into_a_directory_that_holds_files_is_one_line(
    data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "keep.txt").write_text("mine")
    assert cli(["export", str(data), "--format", "lerobot", "--out", str(tmp_path)]) == 2  # a usage error
    assert "already exists and is not an empty directory" in one_error_line(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.txt"]
    assert cli(["export", str(data), "--format", "hdf5", "--out", str(tmp_path / "x")]) == 2
    assert "--format hdf5: unknown export format" in one_error_line(capsys)


def _lerobot_python() -> Path | None:
    configured = os.environ.get("UNITAC_LEROBOT_PYTHON")
    candidate = Path(configured) if configured else REPO / ".venv-lerobot" / "bin" / "python"
    return candidate if candidate.is_file() else None


@pytest.mark.lerobot
def test_lerobot_dataset_loads_the_export_as_written(data: Path, exported: Path, tmp_path: Path) -> None:
    python = _lerobot_python()
    if python is None:
        pytest.skip("no lerobot-dataset environment: .ci/run builds .venv-lerobot (or set UNITAC_LEROBOT_PYTHON)")
    out = tmp_path / "loaded.npz"
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "HF_HOME": str(tmp_path / "hf"), "PYTHONNOUSERSITE": "1"}
    env.pop("PYTHONPATH", None)
    script = Path(__file__).with_name("lerobot_load_check.py")
    done = subprocess.run([str(python), "-I", str(script), str(exported), str(out)], env=env, cwd=tmp_path,
                          capture_output=True, text=True, timeout=600)  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    loaded = np.load(out)
    summary = json.loads(str(loaded["summary"]))
    assert sys.executable != str(python)
    for sensor in SENSORS:
        root = exported / sensor
        info = json.loads((root / "meta/info.json").read_text())
        got = summary[sensor]
        presses = read_presses(data / f"circle_pla__{sensor}.h5")
        assert got["num_episodes"] == len(presses) and got["fps"] == info["fps"]
        assert got["len"] == info["total_frames"] == sum(len(p.tactile_t_s) for p in presses)
        assert got["episode_press_ids"] == [p.press_id for p in presses]
        assert got["episode_lengths"] == [len(p.tactile_t_s) for p in presses]
        assert got["objects"] == ["circle_pla"] and set(got["tasks"]) == {
            "press the circle_pla object (circle PLA) onto the tactile pad to 10 N"
        }
        for name, feature in info["features"].items():  # features as written (LeRobot reads shapes as tuples)
            assert got["features"][name]["dtype"] == feature["dtype"]
            assert list(got["features"][name]["shape"]) == feature["shape"]
        written = json.loads((root / "meta/stats.json").read_text())
        assert got["stats"] == written
        # every frame LeRobot returns is the recorded, tare-subtracted frame of that press
        tared = np.concatenate([p.tactile_values.astype(np.float32) - p.tare_baseline.astype(np.float32)
                                for p in presses])  # fmt: skip
        assert np.array_equal(loaded[f"{sensor}/observation.tactile.{sensor}"], tared)
        assert np.array_equal(loaded[f"{sensor}/index"], np.arange(len(tared)))
        matched = loaded[f"{sensor}/annotation.matched_targets"]
        assert matched.sum() == sum(p.extraction.n_matched for p in presses if p.extraction is not None)

"""``unitac-rig stream``: the trained run on the live sensor. The live model computes what ``translate`` and the
geometry estimator compute; end to end against the real-time twin (a 1 kHz PapillArray) while the arm presses, every
frame the device sent comes out as one JSON line with its latent, its translation and its geometry estimate.

Loopback addresses 127.0.0.160-169 belong to these tests. No timing is asserted here: the latency is measured by
benchmarks/stream_latency.py (docs/benchmarks.md).
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import threading
import tomllib
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import rtde_control
import torch

from tests.helpers import cli, console_script
from tests.learning.learning_helpers import small_sets
from tests.twin.twin_helpers import wait_until
from unitac_rig.learning.contact_geometry import GeometryConfig, GeometryEstimator, geometry_for_run
from unitac_rig.learning.data import PairedDataset, build_paired_dataset
from unitac_rig.learning.live import LiveModel, json_numbers
from unitac_rig.learning.train import TrainConfig, train
from unitac_rig.learning.translate import Translator
from unitac_rig.sim.twin import first_free_loopback
from unitac_rig.sim.twin.rig import RigTwin
from unitac_rig.sim.twin.world import build_scene


@pytest.fixture(scope="module")
def pairs() -> PairedDataset:
    return build_paired_dataset(small_sets())


@pytest.fixture(scope="module")
def run_dir(pairs: PairedDataset, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small UniTac-NV run on uSkin + PapillArray with a fitted geometry estimator."""
    out = tmp_path_factory.mktemp("stream") / "run"
    train(pairs, out, TrainConfig(epochs=30, seeds=(0,), tsne_contacts=30, eval_every=30), device="cpu")
    geometry_for_run(out, config=GeometryConfig(epochs=5))
    return out


def _close(got: np.ndarray, expected: np.ndarray, rel: float = 1e-5) -> None:
    np.testing.assert_allclose(got, expected, rtol=0, atol=rel * max(1.0, float(np.abs(expected).max())))


def test_the_live_model_computes_what_translate_and_the_geometry_estimator_compute(
    run_dir: Path, pairs: PairedDataset
) -> None:
    translator = Translator.load(run_dir)
    estimator = GeometryEstimator.load(run_dir)
    for sensor, other in (("papillarray", "uskin"), ("uskin", "papillarray")):
        frames = pairs.values[sensor][:25]
        model = LiveModel(run_dir, sensor)
        out = model(frames)
        assert model.targets == (other,)
        _close(out.latent, translator.encode(frames, sensor))
        _close(out.translated[other], translator.translate(frames, sensor, other))
        assert out.geometry_mm is not None and model.geometry_meta is not None
        _close(out.geometry_mm, estimator.predict(translator.encode(frames, sensor), model.geometry_meta["trained_on"]))
    assert LiveModel(run_dir, "uskin", geometry=False).geometry is None


def test_numbers_are_json_with_six_significant_digits() -> None:
    values = np.array([[1.23456789, -2e-7, 3.0], [np.inf, 5.5, np.nan]], dtype=np.float32)
    assert json.loads(json_numbers(values[:1])) == [[1.23457, -2e-07, 3.0]]
    assert json.loads(json_numbers(values)) == [[1.23457, -2e-07, 3.0], [None, 5.5, None]]


@pytest.fixture
def twin() -> Iterator[RigTwin]:
    with RigTwin("circle_pla", sensor="papillarray", host=first_free_loopback(160, 169), seed=5) as rig:
        yield rig


def _twin_rig_file(twin: RigTwin, directory: Path) -> Path:
    """The twin's rig file with the PapillArray at 1 kHz (its power-up rate; the file's default is 100 Hz)."""
    text = twin.rig_file().replace("rate_hz = 100", "rate_hz = 1000")
    assert tomllib.loads(text)["sensors"]["papillarray"]["rate_hz"] == 1000
    path = directory / "twin.toml"
    path.write_text(text)
    return path


def test_stream_emits_every_frame_of_the_twin_while_the_arm_presses(
    run_dir: Path, twin: RigTwin, tmp_path: Path
) -> None:
    rig_file = _twin_rig_file(twin, tmp_path)
    summary_path = tmp_path / "summary.json"
    stream = subprocess.Popen(
        [
            console_script(),
            "stream",
            str(run_dir),
            "--rig",
            str(rig_file),
            "--sensor",
            "papillarray",
            "--summary",
            str(summary_path),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    lines: list[bytes] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(stream.stdout.readline, b"")), name="stream-lines")  # type: ignore[union-attr]
    reader.start()
    control = None
    try:
        assert wait_until(lambda: len(lines) > 100 or stream.poll() is not None, 60.0), "no lines from stream"
        assert stream.poll() is None, stream.stderr.read().decode()  # type: ignore[union-attr]
        control = rtde_control.RTDEControlInterface(twin.host, 500.0)
        rest = len(lines)
        pressed = build_scene(twin.spec).pose_at_travel(0.0, 1.5)  # 1.5 mm past first touch, approach angle 0
        assert control.moveL(list(pressed), 0.1, 0.5)
        assert twin.controller.truth().force_n > 1.0
        assert control.moveL(list(twin.controller.settings.start_pose), 0.1, 0.5)
        during = len(lines)
    finally:
        if control is not None:
            control.disconnect()
        stream.send_signal(signal.SIGINT)  # the way a user stops it
        # stdout belongs to the reader thread until EOF (communicate() would read it too, and a line it took
        # would be missing here: seen once, 3312 lines for 3313 frames)
        reader.join(timeout=60)
        stream.wait(timeout=60)
        err = stream.stderr.read()  # type: ignore[union-attr]
    assert not reader.is_alive()
    assert stream.returncode == 130, err.decode()  # Ctrl-C ends the stream as interrupted, after its summary
    assert "run the same command to go on" in err.decode()
    summary = json.loads(summary_path.read_text())
    items = [json.loads(line) for line in lines]
    assert during > rest  # frames kept coming while the arm moved
    # every frame the hub sent after the tare, in order: device counter without a gap, one line each
    assert len(items) == summary["frames_out"] and summary["frames_in"] == summary["frames_out"] + 50
    assert [item["i"] for item in items] == list(range(len(items)))
    seqs = np.array([item["seq"] for item in items])
    assert (np.diff(seqs) == 1).all() and summary["seq_gaps"] == 0 and summary["driver"]["sequence_gaps"] == 0
    assert summary["rate_hz"] > 0 and summary["latency_ms"]["median"] > 0
    # the warm-up backlog is marked, first lines only, and counted apart from the steady state
    warm = [item["warmup"] for item in items]
    assert warm[0] and sum(warm) == summary["warmup"]["frames"] and warm == sorted(warm, reverse=True)
    # each line carries the tared frame the model saw, and its stamp on the wall clock too
    assert np.array([item["frame"] for item in items]).shape == (len(items), 9, 3)
    assert abs(items[-1]["unix_t_ns"] / 1e9 - summary["finished_unix"]) < 60
    assert np.all(np.diff([item["unix_t_ns"] - item["host_t_ns"] for item in items]) == 0)
    # each line: the latent, the frame as the uSkin would see it (what the run's decoder makes of that latent), the
    # geometry estimate
    model = LiveModel(run_dir, "papillarray")
    latents = np.array([item["latent"] for item in items], dtype=np.float32)
    assert latents.shape == (len(items), 16)
    translated = np.array([item["translated"]["uskin"] for item in items])
    assert translated.shape == (len(items), 24, 3)
    with torch.no_grad():
        expected = model.model.decode(torch.from_numpy(latents), "uskin").numpy()
    _close(translated, expected, rel=5e-5)
    assert np.array([item["geometry_mm"] for item in items]).shape == (len(items), 11)
    # the press shows: the latent moves far beyond its resting noise
    moved = np.linalg.norm(latents - latents[:50].mean(axis=0), axis=1)
    assert moved.max() > 10 * np.percentile(moved[:50], 90)


def test_stream_serves_one_local_client_over_a_socket(run_dir: Path, twin: RigTwin, tmp_path: Path) -> None:
    rig_file = _twin_rig_file(twin, tmp_path)
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    stream = subprocess.Popen(
        [
            console_script(),
            "stream",
            str(run_dir),
            "--rig",
            str(rig_file),
            "--sensor",
            "papillarray",
            "--listen",
            f"127.0.0.1:{port}",
            "--frames",
            "200",
            "--no-geometry",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    client: socket.socket | None = None

    def connected() -> bool:
        nonlocal client
        with contextlib.suppress(OSError):
            client = socket.create_connection(("127.0.0.1", port), timeout=60.0)
        return client is not None or stream.poll() is not None

    try:
        assert wait_until(connected, 60.0, poll_s=0.05)
        assert client is not None, stream.stderr.read().decode()  # type: ignore[union-attr]
        received = b""
        with client:
            while chunk := client.recv(1 << 16):
                received += chunk
    finally:
        out, err = stream.communicate(timeout=60)
    assert stream.returncode == 0, err.decode()  # --frames reached: done
    assert out == b""  # the lines went to the client, not stdout
    items = [json.loads(line) for line in received.splitlines()]
    assert len(items) == 200 and "geometry_mm" not in items[0] and len(items[0]["translated"]["uskin"]) == 24


def test_bad_stream_requests_are_one_line_usage_errors(run_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli(["stream", str(run_dir)]) == 2
    assert "stream needs --rig RIG.toml or --simulated" in capsys.readouterr().err
    assert cli(["stream", str(run_dir), "--simulated", "--listen", "0.0.0.0:9000"]) == 2
    assert "127.0.0.1 only" in capsys.readouterr().err

"""Issue 40: every interruption says what it kept and the command that goes on, and keeps what it says; the first
lines of a long command count what is already done; the stream says the rate it achieved and marks its warm-up.

(Ctrl-C in ``collect`` / ``campaign``: tests/robustness/test_safety_and_interrupts.py; in ``stream``, through the
real twin: tests/twin/test_stream.py.)
"""

from __future__ import annotations

import hashlib
import signal
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from drivers.frames import TactileFrame
from tests.helpers import cli, run_console, start_console
from tests.learning.learning_helpers import small_sets, write_sessions
from tests.twin.twin_helpers import wait_until
from unitac_rig.cli.learn import kept_run_line
from unitac_rig.cli.stream import summary_lines
from unitac_rig.interrupts import forget_interrupts, note_interrupt
from unitac_rig.learning.data import build_paired_dataset
from unitac_rig.learning.live import LiveOutput, stream_frames
from unitac_rig.learning.run import load_checkpoint
from unitac_rig.learning.train import TrainConfig, train

# ---- train: the finished epoch is kept, and the line says so -----------------------------------------------------


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Synthetic sessions of three objects with both sensors (the recorder's own files)."""
    root = tmp_path_factory.mktemp("interrupt") / "data"
    write_sessions(root, small_sets())
    return root


def test_ctrl_c_in_train_keeps_the_epoch_it_finished_and_names_the_resume_command(tmp_path: Path) -> None:
    """The CLI defers Ctrl-C to the end of the epoch (unitac_rig.interrupts); train() then checkpoints that epoch,
    though it is no multiple of checkpoint_every, and the line names it and the command that goes on."""
    out = tmp_path / "run"

    def ctrl_c_at_epoch_7(record: dict[str, Any]) -> None:
        if record["epoch"] == 7:
            note_interrupt(signal.SIGINT)  # what the CLI's deferring handler does on Ctrl-C

    try:
        with pytest.raises(KeyboardInterrupt):
            train(
                build_paired_dataset(small_sets()),
                out,
                TrainConfig(epochs=500, checkpoint_every=50),
                device="cpu",
                progress=ctrl_c_at_epoch_7,
            )
    finally:
        forget_interrupts()
    assert load_checkpoint(out)["epoch"] == 7  # nothing trained is lost
    line = kept_run_line(out, [Path("data")])
    assert f"kept epoch 7/500 in {out}" in line
    assert line.endswith(f"go on with: unitac-rig train --data data --out {out} --resume")
    assert "nothing kept" in kept_run_line(tmp_path / "never-trained", [Path("data")])


@pytest.mark.slow
def test_ctrl_c_in_the_train_command_exits_130_with_the_kept_epoch(data_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    train_cmd = start_console(
        "train", "--data", str(data_dir), "--out", str(out), "--epochs", "100000", "--no-baselines", "--no-report"
    )
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(train_cmd.stdout.readline, "")))  # type: ignore[union-attr]
    reader.start()
    try:
        assert wait_until(lambda: any("train: epoch" in line for line in lines) or train_cmd.poll() is not None, 120)
        train_cmd.send_signal(signal.SIGINT)
        train_cmd.wait(timeout=120)
    finally:
        if train_cmd.poll() is None:
            train_cmd.kill()
        reader.join(timeout=60)
    err = train_cmd.stderr.read()  # type: ignore[union-attr]
    assert train_cmd.returncode == 130, err
    kept = load_checkpoint(out)["epoch"]
    assert kept >= 1
    assert f"kept epoch {kept}/100000 in {out}" in err and "--resume" in err


# ---- report: an interrupted report leaves the run's files as they were ------------------------------------------


def test_ctrl_c_during_the_report_leaves_metrics_and_report_as_they_were(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from unitac_rig.learning import report

    out = tmp_path / "run"
    train(build_paired_dataset(small_sets()), out, TrainConfig(epochs=3, tsne_contacts=30), device="cpu")
    report.write_report(out)
    before = {name: (out / name).read_bytes() for name in ("metrics.json", "report.md")}
    assert b"tsne_mixing" in before["metrics.json"]

    def interrupted(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(report, "tsne_embeddings", interrupted)  # Ctrl-C in the slowest step
    with pytest.raises(KeyboardInterrupt):
        report.write_report(out, nmae_normaliser="frame_range")  # other numbers than before
    assert {name: (out / name).read_bytes() for name in before} == before
    capsys.readouterr()
    assert cli(["report", str(out), "--nmae-normaliser", "frame_range"]) == 130
    err = capsys.readouterr().err
    assert f"report: interrupted; {out}/metrics.json and report.md are as they were" in err
    assert f"write them with: unitac-rig report {out}" in err
    assert {name: (out / name).read_bytes() for name in before} == before
    assert not [p.name for p in out.iterdir() if p.name.endswith(".tmp")]


# ---- collect / campaign / inspect: what is done counts, and the command that resumes is named ---------------------


def test_inspect_names_an_unfinished_session_and_its_command_resumes_it(tmp_path: Path) -> None:
    data = tmp_path / "data"
    assert (
        run_console(
            "collect",
            "--object",
            "hex_tpu",
            "--sensor",
            "uskin",
            "--angles",
            "3",
            "--max-presses",
            "1",
            "--data",
            str(data),
            "--no-live",
        ).returncode
        == 0
    )
    shown = " ".join(run_console("inspect", str(data)).stdout.split())
    command = f"unitac-rig collect --object hex_tpu --sensor uskin --data {data} --angles 3"
    assert f"hex_tpu/uskin: incomplete (1 of 3 presses finished); resume: {command}" in shown
    # the campaign's first line counts the press done before it
    campaign = run_console("campaign", "--objects", "hex_tpu", "--angles", "3", "--data", str(data), "--no-live")
    assert campaign.returncode == 0, campaign.stderr
    assert "campaign: session 1/2 (hex_tpu / uskin), 1/6 presses done" in " ".join(campaign.stdout.split())
    assert "incomplete" not in run_console("inspect", str(data)).stdout


# ---- extract: settings that lose most matches change nothing without --force --------------------------------------


def _digest(folder: Path) -> str:
    """The data files (the session lease's lock file notes who read last, the readers' verify-once cache what they
    verified: neither is data)."""
    h = hashlib.sha256()
    for path in sorted(
        p for p in folder.rglob("*") if p.is_file() and p.name not in ("_writer.lock", "_verified.json")
    ):
        h.update(path.name.encode() + path.read_bytes())
    return h.hexdigest()


def test_extract_refuses_settings_that_drop_most_matches_unless_forced(tmp_path: Path) -> None:
    data = tmp_path / "data"
    write_sessions(data, small_sets(objects=("hex_tpu",)))
    before = _digest(data)
    refused = run_console("extract", str(data), "--tolerance", "1e-6")
    assert refused.returncode == 2, refused.stdout + refused.stderr
    assert "would keep 0 of the 110 matched targets (drop 110, 100 %); nothing was changed" in refused.stderr
    assert "--force" in refused.stderr
    assert _digest(data) == before
    forced = run_console("extract", str(data), "--tolerance", "1e-6", "--force")
    assert forced.returncode == 0, forced.stderr
    assert "0 targets matched (was 55)" in forced.stdout
    assert '"targets_matched": 0' in run_console("inspect", str(data), "--json").stdout  # extract and inspect agree


# ---- stream: the rate achieved, and the warm-up apart ----------------------------------------------------------


class _Model:
    sensor = "papillarray"

    def __call__(self, frames: np.ndarray) -> LiveOutput:
        return LiveOutput(frames.reshape(len(frames), -1)[:, :2], {}, None)


class _Sensor:
    """A backlog of 50 tare frames and 30 more waiting at once, then one frame at a time, each stamped after the
    previous line was written (the loop keeps up)."""

    def __init__(self, clock: Callable[[], int]) -> None:
        self.clock, self.polls = clock, 0

    def poll_wait(self, timeout_s: float) -> list[TactileFrame]:
        self.polls += 1
        values = np.full((9, 3), float(self.polls), dtype=np.float32)
        if self.polls == 1:
            return [TactileFrame("papillarray", host_t_ns=i * 1_000_000, values=values, seq=i) for i in range(80)]
        now = self.clock()
        return [TactileFrame("papillarray", host_t_ns=now + 1, values=values, seq=78 + self.polls)]


def test_stream_marks_the_warm_up_backlog_and_reports_the_steady_state_apart() -> None:
    ticks = iter(range(200_000_000, 10**12, 100_000))  # 0.1 ms per clock read, starting 120 ms after the backlog
    now = [0]

    def clock() -> int:
        now[0] = next(ticks)
        return now[0]

    lines: list[bytes] = []
    stats = stream_frames(
        _Sensor(lambda: now[0]), _Model(), lines.append, tare_frames=50, max_frames=130, clock_ns=clock
    )  # type: ignore[arg-type]
    import json

    items = [json.loads(line) for line in lines]
    assert [item["warmup"] for item in items] == [True] * 30 + [False] * 100
    summary = stats.summary()
    assert summary["warmup"]["frames"] == 30 and summary["warmup"]["latency_ms"]["max"] > 150
    assert summary["latency_ms"]["max"] < 1  # the backlog's 150+ ms do not reach the steady state's p99/max
    assert items[0]["frame"] == np.zeros((9, 3)).tolist()  # tared on the first poll's frames
    assert items[-1]["frame"] == np.full((9, 3), 101.0 - 1.0).tolist()
    assert all(item["unix_t_ns"] - item["host_t_ns"] == items[0]["unix_t_ns"] - items[0]["host_t_ns"] for item in items)


def test_the_stream_summary_warns_when_the_rate_falls_short_of_the_one_asked() -> None:
    def summary(rate: float) -> dict[str, Any]:
        latency = {"median": 0.3, "p99": 0.9, "max": 1.2}
        return {
            "frames_out": 1000,
            "seconds": 2.0,
            "rate_hz": rate,
            "asked_rate_hz": 1000,
            "seq_gaps": 0,
            "latency_ms": latency,
            "warmup": {"frames": 40, "seconds": 0.5, "latency_ms": latency},
        }

    slow = "\n".join(summary_lines(summary(480.0)))
    assert "at 480 Hz (asked 1000 Hz)" in slow
    assert "warning: the sensor delivered 480 Hz, 48 % of the 1000 Hz asked" in slow
    assert "warning" not in "\n".join(summary_lines(summary(950.0)))

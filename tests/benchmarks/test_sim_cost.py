"""The simulator-cost benchmark's worker measures one seeded session and reports what it recorded (never timings)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "sim_cost.py"


def test_the_worker_reports_one_session_split_into_simulator_and_host(tmp_path: Path) -> None:
    command = [sys.executable, str(SCRIPT), "--worker", "uskin", "--angles", "2", "--presses", "1", "--seed", "0"]
    done = subprocess.run(command, capture_output=True, text=True, cwd=tmp_path, check=True)
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert (result["sensor"], result["presses_complete"], result["targets_matched"]) == ("uskin", 1, 25)
    assert result["simulated_s"] > 0 and 0 < result["simulator_cpu_s"] < result["cpu_s"]
    per_s = result["simulator_cpu_per_simulated_s"] + result["host_cpu_per_simulated_s"]
    assert abs(per_s - result["cpu_per_simulated_s"]) < 1e-3


def _worker(*args: str, cwd: Path) -> dict[str, object]:
    command = [sys.executable, str(SCRIPT), *args]
    done = subprocess.run(command, capture_output=True, text=True, cwd=cwd, check=True)
    result: dict[str, object] = json.loads(done.stdout.strip().splitlines()[-1])
    return result


def test_the_recorded_digest_covers_the_press_files(tmp_path: Path) -> None:
    """The bit-identity check hashes what each press file holds: sessions of two seeds differ (it hashed nothing
    once press files became external links, and every pair of sessions compared equal)."""
    base = ("--worker", "papillarray", "--angles", "2", "--presses", "1")
    first, again, other = (_worker(*base, "--seed", seed, cwd=tmp_path) for seed in ("0", "0", "1"))
    empty = "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855"  # SHA-256 of nothing
    assert first["recorded_sha256"] == again["recorded_sha256"] != empty
    assert other["recorded_sha256"] != first["recorded_sha256"]


def test_a_recorded_session_replays_on_the_same_code_to_the_same_end(tmp_path: Path) -> None:
    """--same-work's trace holds every call the host made into the simulated rig: replayed open loop on the same
    code, the seeded simulator takes the same path (no call fails, the arm is where it was after every call, to the
    bit)."""
    trace_script = SCRIPT.with_name("sim_trace.py")
    trace = tmp_path / "uskin.trace"
    record = [sys.executable, str(trace_script), "record", "uskin", str(trace), "hex_tpu", "3", "2", "0"]
    subprocess.run(record, capture_output=True, text=True, cwd=tmp_path, check=True)
    replayed = _worker("--replay-worker", str(trace), cwd=tmp_path)
    assert replayed["failed_calls"] == {}
    assert replayed["replayed_simulated_s"] == replayed["simulated_s"]
    assert replayed["replayed_final_tcp_pose"] == replayed["final_tcp_pose"]
    assert replayed["replayed_arm_path_sha256"] == replayed["arm_path_sha256"]  # the pose after every arm call
    assert 0 < float(str(replayed["simulator_share"])) < 1

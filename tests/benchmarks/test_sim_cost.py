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

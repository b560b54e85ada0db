"""One process of the safety benchmark: presses on the fast twin with a host stall or a host death injected.

Run as a script (``python -c 'import runpy; runpy.run_path(PATH, run_name="__main__")' < cases.json``) with
``PYTHONPATH`` pointing at the checkout under test, so the same measurement runs against today's code and against an
older commit (a ``git worktree``): it only uses names both have (SimRig, plan_presses, run_press, collect_session,
the simulated arm's ground truth), and it imports nothing from ``unitac_rig.bench``. Reads a JSON list of cases on
stdin, writes one JSON object per case on stdout.

Stall: the first time the *true* press force passes ``trigger_n``, ``on_tick`` (which runs in the host's control loop)
advances the virtual clock by ``stall_s`` without the host doing anything; the simulated controller executes its last
command meanwhile, as a real one does. Death: the host stops for good at that moment (no stop command, nothing), and
the controller runs on alone for ``DEATH_WATCH_S``.
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

DEATH_WATCH_S = 2.0  # after a host death, watch the controller alone this long (simulated seconds)
REST_SPEED_M_S = 1e-6


class _HostDied(BaseException):
    """Raised from the control loop to end the host there, like kill -9 (nothing that catches Exception stops it)."""


class _Truth:
    """Clock listener: the true press force (N, along the press) and |F|, their peaks, and when the arm last moved."""

    def __init__(self, rig: Any, direction: np.ndarray) -> None:
        self.rig, self.direction = rig, np.asarray(direction, dtype=np.float64)
        self.peak_press_n = 0.0
        self.peak_abs_n = 0.0
        self.last_moving_s = 0.0
        rig.clock.on_advance(self)

    def press_n(self) -> float:
        return -float(np.dot(self.rig.sim_arm.true_wrench()[:3], self.direction))

    def __call__(self, now_ns: int) -> None:
        wrench = self.rig.sim_arm.true_wrench()
        self.peak_press_n = max(self.peak_press_n, -float(np.dot(wrench[:3], self.direction)))
        self.peak_abs_n = max(self.peak_abs_n, float(np.linalg.norm(wrench[:3])))
        speed = self.rig.sim_arm.read_state().tcp_speed
        if speed is not None and float(np.linalg.norm(np.asarray(speed)[:3])) > REST_SPEED_M_S:
            self.last_moving_s = now_ns / 1e9


def _advance(rig: Any, seconds: float) -> None:
    """Let the controller run alone for ``seconds``, one 2 ms period at a time (so the truth sees every period)."""
    for _ in range(round(seconds / 0.002)):
        rig.clock.advance_ns(2_000_000)


def _tare(rig: Any, sensor: Any, plan: Any) -> None:
    from unitac_rig.collection import session

    tare = getattr(session, "session_tare", None) or getattr(session, "_session_tare")  # noqa: B009 - the old name
    tare(rig, sensor, plan)


def stall_case(case: dict[str, Any]) -> dict[str, Any]:
    """One press with a stall (``stall_s``) or a death (``stall_s`` None) at ``trigger_n``; -> what the truth saw."""
    from unitac_rig.collection.press import run_press
    from unitac_rig.collection.session import plan_presses
    from unitac_rig.rig.config import parse_rig_config
    from unitac_rig.rig.objects import get_object
    from unitac_rig.sim.fast_rig import SimRig

    angle = case["angle_deg"]
    press = {"strategy": case["strategy"], "angle_count": 1, "angle_min_deg": angle, "angle_max_deg": angle}
    config = parse_rig_config({"press": press})
    obj = get_object(case["object_id"])
    (plan,) = plan_presses(obj, config, [0.0])
    death = case["stall_s"] is None
    out: dict[str, Any] = {**case}
    rig: Any
    with SimRig(config, seed=case["seed"]) as rig:
        sensor = rig.open_sensor("uskin")
        try:
            rig.mount(obj, 0.0, "uskin")
            _tare(rig, sensor, plan)
            truth = _Truth(rig, plan.direction)
            fired: list[float] = []

            def inject(_tick: Any) -> None:
                if fired or truth.press_n() < case["trigger_n"]:
                    return
                fired.append(rig.clock.now_ns() / 1e9)
                if death:
                    for name in (
                        "stop",
                        "force_mode_stop",
                        "speed_linear",
                        "force_mode",
                        "move_linear",
                        "start_move_linear",
                        "zero_ft",
                    ):
                        if hasattr(rig.sim_arm, name):
                            setattr(rig.sim_arm, name, lambda *a, **k: None)  # a dead host sends nothing
                    raise _HostDied
                _advance(rig, case["stall_s"])

            try:
                record = run_press(rig.arm, sensor, plan, config.press, config.limits, on_tick=inject)
                out["status"], out["reason"] = record.status, record.reason
            except _HostDied:
                out["status"], out["reason"] = "host_died", "host_died"
                _advance(rig, DEATH_WATCH_S)
            except Exception as exc:  # the press ended another way (hard limit, protective stop, watchdog...)
                out["status"], out["reason"] = "aborted", type(exc).__name__
            out["triggered"] = bool(fired)
            out["peak_press_n"] = truth.peak_press_n
            out["peak_abs_n"] = truth.peak_abs_n
            if death and fired:
                speed = rig.sim_arm.read_state().tcp_speed
                moving = speed is not None and float(np.linalg.norm(np.asarray(speed)[:3])) > REST_SPEED_M_S
                out["rest_after_last_write_s"] = None if moving else max(0.0, truth.last_moving_s - fired[0])
                out["protective_stop"] = bool(rig.sim_arm.read_state().protective_stop)
        finally:
            sensor.disconnect()
    return out


def session_case(case: dict[str, Any]) -> dict[str, Any]:
    """A short session of one strategy: per press the recorded and the true overshoot, and the matching errors."""
    from unitac_rig.collection.session import collect_session
    from unitac_rig.rig.config import parse_rig_config
    from unitac_rig.rig.objects import get_object
    from unitac_rig.sim.fast_rig import SimRig

    config = parse_rig_config({"press": {"strategy": case["strategy"], "angle_count": case["angles"]}})
    obj = get_object(case["object_id"])
    presses: list[dict[str, Any]] = []
    truth_peak: dict[str, Any] = {"n": 0.0, "id": None}
    rig: Any
    with tempfile.TemporaryDirectory() as tmp, SimRig(config, seed=case["seed"]) as rig:

        def on_tick(tick: Any) -> None:
            if tick.press_id != truth_peak["id"]:
                truth_peak.update(n=0.0, id=tick.press_id)
            from unitac_rig.rig.poses import approach_direction

            angle = float(tick.press_id.split("_ang")[1])
            direction = -approach_direction(angle)
            truth_peak["n"] = max(truth_peak["n"], -float(np.dot(rig.sim_arm.true_wrench()[:3], direction)))

        def on_press(done: Any) -> None:
            record = done.record
            extraction = record.extraction
            errors = np.asarray(extraction.error_n, dtype=np.float64)
            miss = np.asarray(extraction.miss, dtype=bool)
            presses.append(
                {
                    "press_id": record.press_id,
                    "status": record.status,
                    "recorded_peak_n": float(record.attrs.get("peak_force_n", np.nan)),
                    "true_peak_n": truth_peak["n"],
                    "abs_errors_n": [abs(float(e)) for e, m in zip(errors, miss, strict=True) if not m],
                    "misses": int(miss.sum()),
                    "targets": len(miss),
                    "duration_s": float(record.attrs.get("duration_s", np.nan)),
                }
            )

        collect_session(rig, obj, case["sensor"], Path(tmp), rotations=[0.0], on_press=on_press, on_tick=on_tick)
    return {**case, "presses": presses}


def main() -> None:
    cases = json.load(sys.stdin)
    for case in cases:
        result = session_case(case) if case.get("kind") == "session" else stall_case(case)
        sys.stdout.write(json.dumps(result) + "\n")
        sys.stdout.flush()


if __name__ == "__main__":
    main()

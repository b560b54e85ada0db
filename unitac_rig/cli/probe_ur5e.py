"""``unitac-rig probe ur5e``: read a few states from a UR controller over RTDE, read-only (the arm never moves).

``probe ur5e --host 192.168.1.10`` prints one line per state (host time, controller time, TCP pose in mm/rad, TCP
force in N, robot mode, protective stop); ``--json`` prints one JSON object per state instead. ``--simulated``
starts a simulated controller (a still arm) on a free loopback address and reads it with the real ur_rtde client.
An unreachable host ends with one error line and exit status 1.
"""

from __future__ import annotations

import contextlib
import json
from typing import Any

import typer

from drivers.arm import ArmState
from unitac_rig.errors import UsageError


def state_json(state: ArmState) -> dict[str, Any]:
    """One state as a ``--json`` line: host time (s); RTDE has no sequence counter, so ``seq`` is null."""
    return {
        "sensor": "ur5e",
        "t": state.host_t_ns / 1e9,
        "seq": None,
        "controller_t": state.controller_t_s,
        "tcp_pose": [float(v) for v in state.tcp_pose],
        "tcp_force": [float(v) for v in state.tcp_force],
        "robot_mode": int(state.robot_mode),
        "safety_mode": int(state.safety_mode),
        "protective_stop": bool(state.protective_stop),
    }


def state_line(state: ArmState) -> str:
    """One state as a readable line: position in mm, rotation vector in rad, force in N, torque in N*m."""
    pose, force = state.tcp_pose, state.tcp_force
    position_mm = " ".join(f"{1000 * v:8.2f}" for v in pose[:3])
    rotation = " ".join(f"{v:+.3f}" for v in pose[3:])
    forces = " ".join(f"{v:+7.2f}" for v in force[:3])
    torques = " ".join(f"{v:+.3f}" for v in force[3:])
    stop = "PROTECTIVE STOP" if state.protective_stop else ("EMERGENCY STOP" if state.emergency_stop else "ok")
    return (
        f"t={state.host_t_ns / 1e9:.4f}s ctrl={state.controller_t_s:.3f}s "
        f"xyz=[{position_mm}] mm rv=[{rotation}] F=[{forces}] N T=[{torques}] N*m "
        f"mode={state.robot_mode} safety={state.safety_mode} {stop}"
    )


def register_ur5e(probe_app: typer.Typer) -> None:
    """Add ``probe ur5e`` to the probe sub-app."""

    @probe_app.command("ur5e")
    def probe_ur5e(
        host: str | None = typer.Option(None, "--host", help="Robot IP address or host name."),
        frames: int = typer.Option(10, "--frames", min=1, help="How many states to read."),
        as_json: bool = typer.Option(False, "--json", help="Print one JSON object per state."),
        timeout: float = typer.Option(5.0, "--timeout", min=0.1, help="Give up when no new state arrives (s)."),
        simulated: bool = typer.Option(
            False, "--simulated", help="Start a simulated controller (still arm) on a free loopback address."
        ),
    ) -> None:
        """Read TCP pose, TCP force, robot mode and protective stop from a UR over RTDE (read-only)."""
        from drivers.ur5e import UR5eReceiver

        if host is None and not simulated:
            raise UsageError("probe ur5e needs --host", hint="e.g. --host 192.168.1.10, or --simulated")
        with contextlib.ExitStack() as stack:
            if simulated:
                from unitac_rig.sim.rtde_server import start_on_free_loopback

                host = stack.enter_context(start_on_free_loopback()).host
            assert host is not None
            receiver = stack.enter_context(UR5eReceiver(host))
            for _ in range(frames):
                state = receiver.wait_for_new_state(timeout_s=timeout)
                typer.echo(json.dumps(state_json(state)) if as_json else state_line(state))

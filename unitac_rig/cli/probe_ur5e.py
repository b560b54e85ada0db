"""``unitac-rig probe ur5e``: read a few states from a UR controller over RTDE, read-only (the arm never moves).

``probe ur5e --host 192.168.1.10`` prints one line per state (host time, controller time, TCP pose in mm/rad, TCP
force in N, robot mode, protective stop); ``--json`` prints one JSON object per state instead. ``--simulated``
starts the controller twin (a still arm, no object: the wrist reads its bias and noise) on a free loopback address
and reads it with the real ur_rtde client.
An unreachable host ends with one error line and exit status 1.

``probe ur5e --host ... --sign-check`` is the wrist-force sign check of the first-run checklist: it asks the operator
to push the pad face back toward the flange by hand, the way the object will push on it, and checks that the wrist
reads that as a *positive* press force along the tool's z axis (the press direction). A wrong TCP rotation on the
pendant, or a sign convention that differs from the one the press code assumes, shows up here instead of as a press
that never stops. Like the rest of ``probe``, it only reads: the arm is never commanded.
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Callable
from typing import Any

import numpy as np
import typer

from drivers.arm import ArmState
from drivers.clock import Clock, MonotonicClock
from unitac_rig.errors import SafetyLimit, UsageError
from unitac_rig.rig.poses import press_force_n, tool_z

SIGN_CHECK_PUSH_N = 5.0  # a push counts once the wrist force changed by this much from the baseline, N
SIGN_CHECK_HOLD_S = 0.2  # ... for this long (one bump of the table is not a push)
SIGN_CHECK_BASELINE_S = 0.5  # the baseline is the mean force over this long with nothing touching the pad
SIGN_CHECK_MIN_ALONG = 0.7  # the push must be mostly along the tool z axis (cosine of the angle to it)


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
    """One state as three readable lines under 80 columns: times and modes; TCP position (mm) and rotation vector
    (rad); force (N) and torque (N*m)."""
    pose, force = state.tcp_pose, state.tcp_force
    position_mm = " ".join(f"{1000 * v:8.2f}" for v in pose[:3])
    rotation = " ".join(f"{v:+.3f}" for v in pose[3:])
    forces = " ".join(f"{v:+7.2f}" for v in force[:3])
    torques = " ".join(f"{v:+.3f}" for v in force[3:])
    stop = "PROTECTIVE STOP" if state.protective_stop else ("EMERGENCY STOP" if state.emergency_stop else "ok")
    return (
        f"t {state.host_t_ns / 1e9:.4f} s  controller {state.controller_t_s:.3f} s  mode {state.robot_mode}  "
        f"safety {state.safety_mode}  {stop}\n"
        f"  xyz {position_mm} mm    rv {rotation} rad\n"
        f"  F   {forces} N     T  {torques} N*m"
    )


def sign_check_verdict(baseline: np.ndarray, pushed: np.ndarray, tcp_pose: np.ndarray) -> tuple[bool, str]:
    """Judge a hand push on the pad face: -> (sign right, one line saying what the wrist read).

    ``baseline`` and ``pushed``: mean wrench (6,) before and during the push (N); ``tcp_pose``: (6,) with the tool z
    axis = the press direction. Right means the press force (minus the force along tool z) is positive and the push
    is mostly along that axis.
    """
    change = np.asarray(pushed, dtype=np.float64)[:3] - np.asarray(baseline, dtype=np.float64)[:3]
    axis = tool_z(tcp_pose)
    along = press_force_n(np.concatenate([change, np.zeros(3)]), axis)
    magnitude = float(np.linalg.norm(change))
    fraction = abs(along) / magnitude if magnitude > 0 else 0.0
    reading = f"the push read {along:+.1f} N along the press direction (|F| change {magnitude:.1f} N)"
    if fraction < SIGN_CHECK_MIN_ALONG:
        return False, (
            f"{reading}: mostly sideways; push straight on the pad face, or check the TCP rotation on the pendant "
            "(tool z must point out of the pad)"
        )
    if along < 0:
        return False, (
            f"{reading}: the sign is reversed; check the TCP rotation on the pendant (tool z must point out of the "
            "pad, toward the object) before any press"
        )
    return True, f"{reading}: sign OK"


def run_sign_check(
    read_state: Callable[[], ArmState],
    *,
    echo: Callable[[str], None],
    timeout_s: float,
    clock: Clock | None = None,
    poll_s: float = 0.002,
) -> str:
    """Baseline, ask for a push, wait for it (held for ``SIGN_CHECK_HOLD_S``), judge it; -> the verdict line.

    Raises SafetyLimit with the verdict when the sign is wrong, UsageError when no push came within ``timeout_s``.
    """
    clock = clock or MonotonicClock()

    def collect(seconds: float) -> list[ArmState]:
        states, end = [], clock.now_ns() + round(seconds * 1e9)
        while clock.now_ns() < end:
            states.append(read_state())
            clock.sleep(poll_s)
        return states

    first = collect(SIGN_CHECK_BASELINE_S)
    baseline = np.mean([s.tcp_force for s in first], axis=0)
    echo(
        f"baseline |F| {np.linalg.norm(baseline[:3]):.1f} N. Now push the pad face back toward the flange by hand "
        f"(as the object will), with more than {SIGN_CHECK_PUSH_N:g} N, and hold it for a moment."
    )
    deadline = clock.now_ns() + round(timeout_s * 1e9)
    held: list[ArmState] = []
    while clock.now_ns() < deadline:
        state = read_state()
        pushing = float(np.linalg.norm(np.asarray(state.tcp_force)[:3] - baseline[:3])) > SIGN_CHECK_PUSH_N
        held = [*held, state] if pushing else []
        if held and (held[-1].host_t_ns - held[0].host_t_ns) / 1e9 >= SIGN_CHECK_HOLD_S:
            pushed = np.mean([s.tcp_force for s in held], axis=0)
            ok, line = sign_check_verdict(baseline, pushed, np.asarray(held[-1].tcp_pose))
            if not ok:
                raise SafetyLimit(f"wrist-force sign check failed: {line}")
            return line
        clock.sleep(poll_s)
    raise UsageError(
        f"no push on the pad within {timeout_s:g} s (the wrist force never changed by {SIGN_CHECK_PUSH_N:g} N)",
        hint="rerun and push the pad face by hand while the check waits",
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
            False, "--simulated", help="Start the controller twin (still arm) on a free loopback address."
        ),
        sign_check: bool = typer.Option(
            False, "--sign-check", help="Check the wrist-force sign: push the pad by hand when asked (read-only)."
        ),
        push_timeout: float = typer.Option(30.0, "--push-timeout", min=1.0, help="--sign-check: wait this long, s."),
    ) -> None:
        """Read TCP pose, TCP force, robot mode and protective stop from a UR over RTDE (read-only)."""
        from drivers.ur5e import UR5eReceiver

        if host is None and not simulated:
            raise UsageError("probe ur5e needs --host", hint="e.g. --host 192.168.1.10, or --simulated")
        with contextlib.ExitStack() as stack:
            if simulated:
                from unitac_rig.sim.twin import start_twin_on_free_loopback

                host = stack.enter_context(start_twin_on_free_loopback(2)).host
            assert host is not None
            receiver = stack.enter_context(UR5eReceiver(host))
            if sign_check:
                typer.echo(run_sign_check(receiver.read_state, echo=typer.echo, timeout_s=push_timeout))
                return
            for _ in range(frames):
                state = receiver.wait_for_new_state(timeout_s=timeout)
                typer.echo(json.dumps(state_json(state)) if as_json else state_line(state))

"""The same work for two simulators: record what a session's host asks of the fast twin, replay it on another version.

A session's CPU per simulated second depends on the work packed into each simulated second, and issue 27's press
routine (items 1-3) packs more into each one: force-mode approach and loading instead of slow guarded moves and long
settles. To compare two simulators on the same work, :func:`record` runs a seeded session of this checkout and logs,
in order, every call its host makes into the simulated rig (the arm's commands and state reads, virtual-clock
sleeps, the sensor drivers' connect/poll/tare/..., mount and open_sensor); :func:`replay` makes those calls, open
loop, on the simulated rig of whatever code is on ``sys.path``. The replay advances the simulated clock by the same
control periods and asks for the same reads, so both versions simulate the same arm modes, sensor samples and
seconds; how the replayed arm moves can differ a little where the versions' scenes differ (the host's stop decisions
are replayed, not taken again). Only the driver and rig API is assumed, which 2813621 and later share.

Used by ``benchmarks/sim_cost.py --same-work``; run alone: ``python benchmarks/sim_trace.py record uskin TRACE`` and
``python benchmarks/sim_trace.py replay TRACE``.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import pickle
import sys
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

_ARM_CALLS = (
    "wait_period",
    "read_state",
    "start_move_linear",
    "move_linear",
    "move_running",
    "speed_linear",
    "stop",
    "stop_linear",
    "zero_ft",
    "force_mode",
    "force_mode_stop",
    "set_force_mode_parameters",
    "set_watchdog",
    "kick_watchdog",
    "reupload_script",
    "stop_program",
    "unlock_protective_stop",
)
_SENSOR_CALLS = ("connect", "disconnect", "reconnect", "poll", "poll_wait", "tare", "identity", "health")
_RIG_CALLS = ("mount", "open_sensor", "sensor_answers", "detect_sensor", "check_sensor", "close")


def _portable(value: Any) -> Any:
    """An argument as the trace keeps it: arrays copied, an object spec by its id, frames by their count."""
    if isinstance(value, np.ndarray):
        return value.copy()
    if hasattr(value, "rotations_deg") and hasattr(value, "id"):
        return ("object", value.id)
    if isinstance(value, list) and value and hasattr(value[0], "host_t_ns"):
        return ("frames", len(value))
    return value


class _Recorder:
    """Wraps the simulated rig's classes while a session runs; only calls from the host (depth 0) are logged."""

    def __init__(self) -> None:
        self.events: list[tuple[Any, ...]] = []
        self.depth = 0
        self.sensors: dict[int, int] = {}  # id(driver) -> its number in the trace
        self.path = hashlib.sha256()  # the arm's true pose after each of the host's arm calls

    def wrap(self, owner: str, function: Callable[..., Any], name: str) -> Callable[..., Any]:
        @functools.wraps(function)
        def logged(target: Any, *args: Any, **kwargs: Any) -> Any:
            if self.depth == 0:
                who = self.sensors.get(id(target)) if owner == "sensor" else None
                if owner != "sensor" or who is not None:
                    args_kept = tuple(_portable(a) for a in args)
                    kwargs_kept = {k: _portable(v) for k, v in kwargs.items()}
                    self.events.append((owner, who, name, args_kept, kwargs_kept))
            self.depth += 1
            try:
                result = function(target, *args, **kwargs)
            finally:
                self.depth -= 1
            if owner == "arm" and self.depth == 0:
                self.path.update(target.true_tcp_pose().tobytes())
            if owner == "rig" and name == "open_sensor" and self.depth == 0:
                self.sensors[id(result)] = len(self.sensors)
                self.events.append(("opened", len(self.sensors) - 1, type(result).__name__, (), {}))
            return result

        return logged

    def wrap_keep_alive(self, original: Callable[[Any], Any]) -> Callable[[Any], Any]:
        """``arm.keep_alive()``: its entry and exit are logged (the watchdog counts as fed in between); the host
        code inside it is still the host's."""

        @contextlib.contextmanager
        def logged(target: Any) -> Iterator[None]:
            top = self.depth == 0
            if top:
                self.events.append(("arm", None, "keep_alive_enter", (), {}))
            context = original(target)
            self.depth += 1
            try:
                context.__enter__()
            finally:
                self.depth -= 1
            try:
                yield
            finally:
                if top:
                    self.events.append(("arm", None, "keep_alive_exit", (), {}))
                self.depth += 1
                try:
                    context.__exit__(None, None, None)
                finally:
                    self.depth -= 1

        return logged

    @contextlib.contextmanager
    def installed(self, classes: dict[str, list[type]]) -> Iterator[None]:
        calls = {"arm": _ARM_CALLS, "sensor": _SENSOR_CALLS, "rig": _RIG_CALLS, "clock": ("sleep",)}
        saved: list[tuple[type, str, Any]] = []
        try:
            for owner, kinds in classes.items():
                for cls in kinds:
                    for name in calls[owner]:
                        original = cls.__dict__.get(name)
                        if original is None:
                            for base in cls.__mro__[1:]:
                                if name in base.__dict__:
                                    original = base.__dict__[name]
                                    break
                        if original is None or not callable(original):
                            continue
                        saved.append((cls, name, cls.__dict__.get(name)))
                        setattr(cls, name, self.wrap(owner, original, name))
                if owner == "arm":
                    for cls in kinds:
                        saved.append((cls, "keep_alive", cls.__dict__.get("keep_alive")))
                        cls.keep_alive = self.wrap_keep_alive(cls.keep_alive)
            yield
        finally:
            for cls, name, before in reversed(saved):
                if before is None:
                    delattr(cls, name)
                else:
                    setattr(cls, name, before)


def record(sensor: str, object_id: str, angles: int, presses: int | None, seed: int, trace: Path) -> dict[str, Any]:
    """Run one seeded session of this code and write the host's calls into the simulated rig to ``trace``."""
    from drivers.clock import VirtualClock
    from unitac_rig.collection.session import collect_session
    from unitac_rig.rig.config import parse_rig_config
    from unitac_rig.rig.objects import get_object
    from unitac_rig.sim.arm import SimArm
    from unitac_rig.sim.fast_rig import SimRig

    rig = SimRig(parse_rig_config({"press": {"angle_count": angles}}), seed=seed)
    recorder = _Recorder()
    driver_classes = _driver_classes()
    with (
        tempfile.TemporaryDirectory() as tmp,
        recorder.installed({"arm": [SimArm], "sensor": driver_classes, "rig": [SimRig], "clock": [VirtualClock]}),
    ):
        outcome = collect_session(rig, get_object(object_id), sensor, Path(tmp), max_presses=presses)
    simulated_s = rig.clock.now_ns() / 1e9
    final_pose = rig.sim_arm.true_tcp_pose().tolist()
    rig.close()
    header = {"sensor": sensor, "object": object_id, "angles": angles, "seed": seed, "simulated_s": simulated_s}
    header["final_tcp_pose"] = final_pose
    header["arm_path_sha256"] = recorder.path.hexdigest()
    with trace.open("wb") as f:
        pickle.dump({"header": header, "events": recorder.events}, f, protocol=pickle.HIGHEST_PROTOCOL)
    return {**header, "events": len(recorder.events), "presses_complete": outcome.complete}


def _driver_classes() -> list[type]:
    """The sensor driver classes of the code on ``sys.path`` (their public calls are the host's)."""
    import drivers.papillarray as papillarray
    import drivers.uskin as uskin

    found: list[type] = []
    for module in (uskin, papillarray):
        for value in vars(module).values():
            if isinstance(value, type) and value.__module__ == module.__name__ and hasattr(value, "poll"):
                found.append(value)
    return found


def replay(trace: Path, on_start: Callable[[], None] | None = None) -> dict[str, Any]:
    """Make the calls in ``trace`` on the simulated rig of the code on ``sys.path``; -> what it did.

    ``on_start`` runs once the rig exists, just before the first call (start the CPU measurement there)."""
    from unitac_rig.rig.config import parse_rig_config
    from unitac_rig.rig.objects import get_object
    from unitac_rig.sim.fast_rig import SimRig

    with trace.open("rb") as f:
        data = pickle.load(f)
    header, events = data["header"], data["events"]
    rig = SimRig(parse_rig_config({"press": {"angle_count": header["angles"]}}), seed=header["seed"])
    drivers: dict[int, Any] = {}
    polled: dict[int, list[Any]] = {}
    failures: dict[str, int] = {}

    def argument(value: Any, who: int | None) -> Any:
        if isinstance(value, tuple) and len(value) == 2 and value[0] == "object":
            return get_object(value[1])
        if isinstance(value, tuple) and len(value) == 2 and value[0] == "frames":
            return polled.get(who if who is not None else -1, [])[-value[1] :]
        return value

    opened: list[Any] = []
    kept_alive: list[Any] = []
    path = hashlib.sha256()  # as the recorder's: equal on the recorded code, the replay took the recorded path
    if on_start is not None:
        on_start()
    for owner, who, name, args, kwargs in events:
        if owner == "opened":
            drivers[who] = opened.pop(0)
            continue
        if name == "keep_alive_enter":
            context = rig.sim_arm.keep_alive()
            context.__enter__()
            kept_alive.append(context)
            continue
        if name == "keep_alive_exit":
            kept_alive.pop().__exit__(None, None, None)
            continue
        target = {"arm": rig.sim_arm, "rig": rig, "clock": rig.clock}.get(owner) or drivers.get(who)
        if target is None:
            continue
        call_args = [argument(a, who) for a in args]
        call_kwargs = {k: argument(v, who) for k, v in kwargs.items()}
        try:
            result = getattr(target, name)(*call_args, **call_kwargs)
        except Exception as exc:  # the recorded host saw something else here; the work goes on
            failures[type(exc).__name__] = failures.get(type(exc).__name__, 0) + 1
            continue
        if owner == "arm":
            path.update(rig.sim_arm.true_tcp_pose().tobytes())
        if owner == "rig" and name == "open_sensor":
            opened.append(result)
        elif owner == "sensor" and name in ("poll", "poll_wait") and result:
            kept = polled.setdefault(who, [])
            kept.extend(result)
            del kept[:-2000]
    simulated_s = rig.clock.now_ns() / 1e9
    final_pose = rig.sim_arm.true_tcp_pose().tolist()
    rig.close()
    return {
        **header,
        "replayed_simulated_s": simulated_s,
        "replayed_final_tcp_pose": final_pose,
        "replayed_arm_path_sha256": path.hexdigest(),
        "events": len(events),
        "failed_calls": failures,
    }


def main() -> None:
    if len(sys.argv) >= 4 and sys.argv[1] == "record":  # record SENSOR TRACE [OBJECT ANGLES PRESSES SEED]
        object_id, angles, presses, seed = (sys.argv[4:8] + ["hex_tpu", "91", "30", "0"][len(sys.argv[4:8]) :])[:4]
        print(record(sys.argv[2], object_id, int(angles), int(presses) or None, int(seed), Path(sys.argv[3])))
    elif len(sys.argv) == 3 and sys.argv[1] == "replay":
        print(replay(Path(sys.argv[2])))
    else:
        raise SystemExit(__doc__)


if __name__ == "__main__":
    main()

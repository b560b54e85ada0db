"""The parent's handle on a controller twin: start it, read its ground truth, pull its test hooks, stop it."""

from __future__ import annotations

import contextlib
import errno
import json
import logging
import os
import select
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np

from drivers.errors import DeviceError
from unitac_rig.sim.arm import DEFAULT_START_POSE
from unitac_rig.sim.twin.params import CONTROLLER_PORTS, ControllerParams, SceneSpec, TwinSettings
from unitac_rig.sim.twin.truth import TruthBlock, TwinTruth

logger = logging.getLogger(__name__)

_START_TIMEOUT_S = 20.0  # a fresh interpreter importing numpy and the scene on a loaded 2-core box
_HOOK_TIMEOUT_S = 10.0
_STOP_TIMEOUT_S = 5.0
_PACKAGE_ROOT = str(Path(__file__).resolve().parents[3])  # the directory that holds unitac_rig/


class AddressTaken(DeviceError):
    """The controller twin could not bind one of its ports on that address."""


class ControllerTwin:
    """A simulated UR e-Series controller in its own process, serving 29999/30003/30004 on ``host`` (127.0.0.x).

    The unmodified ``rtde_control.RTDEControlInterface(host)`` and ``rtde_receive.RTDEReceiveInterface(host)``
    connect to it and drive a simulated arm in real time. ``scene`` puts an object in front of the arm (the wrist
    force is the scene's contact force); ``start_pose`` is the pad's pose (m, rad); ``params`` sets what the
    controller answers and its safety limits. Raises :class:`AddressTaken` when a port on ``host`` is in use.

    Ground truth: :meth:`truth` (a :class:`TwinTruth` snapshot, read from shared memory without a round trip) and
    :meth:`true_pad_pose`. Test hooks: :meth:`reset_peak`, :meth:`reset_timing`, :meth:`emergency_stop`,
    :meth:`release_emergency_stop`, :meth:`trigger_protective_stop`, :meth:`set_placement_error`,
    :meth:`set_remote_control`, :meth:`set_pendant_tcp`; :meth:`status` for the program
    state and last error.

    Disconnect every ur_rtde client *before* :meth:`close`: a controller that vanishes under a connected control
    client makes its next blocking command wait 300 s.
    """

    def __init__(
        self,
        host: str = "127.0.0.2",
        *,
        scene: SceneSpec | None = None,
        start_pose: np.ndarray | tuple[float, ...] | None = None,
        params: ControllerParams | None = None,
        seed: int = 0,
    ) -> None:
        self.host = host
        self.params = params or ControllerParams()
        self.scene = scene
        pose = tuple(float(v) for v in (DEFAULT_START_POSE if start_pose is None else start_pose))
        self.settings = TwinSettings(host=host, start_pose=pose, params=self.params, scene=scene, seed=seed)
        self._closed = False
        self._lock = threading.Lock()
        self._file = tempfile.TemporaryFile()  # noqa: SIM115 - lives as long as the twin; closed in close()
        self._file.truncate(TruthBlock.size)
        self._truth = TruthBlock(self._file.fileno())
        environment = dict(os.environ)
        environment["PYTHONPATH"] = os.pathsep.join(filter(None, [_PACKAGE_ROOT, environment.get("PYTHONPATH")]))
        command = [sys.executable, "-m", "unitac_rig.sim.twin.process", "--truth-fd", str(self._file.fileno())]
        self._process = subprocess.Popen(
            command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, pass_fds=(self._file.fileno(),), env=environment
        )
        try:
            assert self._process.stdin is not None
            self._process.stdin.write((self.settings.to_json() + "\n").encode())
            self._process.stdin.flush()
            self._await_ready()
        except BaseException:
            self._shut_down()
            raise
        logger.debug("controller twin on %s (pid %d)", host, self._process.pid)

    def _await_ready(self) -> None:
        assert self._process.stdout is not None
        line = b""
        ready, _, _ = select.select([self._process.stdout], [], [], _START_TIMEOUT_S)
        if ready:
            line = self._process.stdout.readline()
        word, _, rest = line.decode("utf-8", "replace").strip().partition(" ")
        if word == "ready":
            self._await_first_truth()
            return
        if word == "error":
            code, _, why = rest.partition(" ")
            message = f"controller twin cannot listen on {self.host}: {why}"
            if int(code or 0) == errno.EADDRINUSE:
                raise AddressTaken(message, hint="another controller twin (or URSim) uses this address; try another")
            raise DeviceError(message, hint="use a loopback address such as 127.0.0.2")
        exit_code = self._process.poll()
        why = f"it exited with status {exit_code}" if exit_code is not None else f"no answer in {_START_TIMEOUT_S} s"
        raise DeviceError(
            f"the controller twin's process did not start ({why})",
            hint="see its error output above; is unitac-rig installed in this Python environment?",
        )

    def _await_first_truth(self) -> None:
        """The controller says "ready" when it listens; its first cycle publishes the truth a moment later (on a
        loaded box, later than a caller's first :meth:`truth`). Wait for it, so a started twin always has a state."""
        deadline = time.monotonic() + _START_TIMEOUT_S
        while self._truth.read() is None:
            if self._process.poll() is not None or time.monotonic() > deadline:
                raise DeviceError(
                    f"the controller twin listens but published no state within {_START_TIMEOUT_S} s",
                    hint="is the machine overloaded?",
                )
            time.sleep(0.005)

    # ---- ground truth ---------------------------------------------------------------------------------------

    @property
    def pid(self) -> int:
        return self._process.pid

    def truth(self) -> TwinTruth:
        """The controller's state this cycle (what really happens, not what RTDE reports)."""
        snapshot = self._truth.read()
        if snapshot is None:
            raise DeviceError("the controller twin has not published its state", hint="is its process alive?")
        return snapshot

    def true_pad_pose(self) -> np.ndarray:
        """Pose (6,) of the physical tool, the pad centre (m, rad): what the scene and the sensors feel."""
        pose = self._truth.read_pad_pose()
        if pose is None:
            return np.asarray(self.settings.start_pose, dtype=np.float64)
        return pose

    def wait_for(self, condition: Callable[[TwinTruth], bool], timeout_s: float = 5.0, poll_s: float = 0.002) -> bool:
        """Poll the truth until ``condition`` holds (True) or ``timeout_s`` of wall time passes (False)."""
        deadline = time.monotonic() + timeout_s
        while True:
            if condition(self.truth()):
                return True
            if time.monotonic() > deadline:
                return False
            time.sleep(poll_s)

    # ---- hooks ----------------------------------------------------------------------------------------------

    def _hook(self, op: str, **fields: Any) -> dict[str, Any]:
        with self._lock:
            if self._closed or self._process.poll() is not None:
                raise DeviceError("the controller twin is not running")
            assert self._process.stdin is not None and self._process.stdout is not None
            self._process.stdin.write((json.dumps({"op": op, **fields}) + "\n").encode())
            self._process.stdin.flush()
            ready, _, _ = select.select([self._process.stdout], [], [], _HOOK_TIMEOUT_S)
            if not ready:
                raise DeviceError(f"the controller twin did not answer the {op!r} hook in {_HOOK_TIMEOUT_S} s")
            reply: dict[str, Any] = json.loads(self._process.stdout.readline())
        if not reply.get("ok"):
            raise DeviceError(f"controller twin hook {op!r} failed: {reply.get('error')}")
        return reply

    def reset_peak(self) -> None:
        """Start a new peak-force window (the peak becomes the force now)."""
        self._hook("reset_peak")

    def reset_timing(self) -> None:
        """Start a new window for the cycle-timing statistics (worst lateness, late and skipped cycles)."""
        self._hook("reset_timing")

    def emergency_stop(self) -> None:
        """Press the emergency stop: the arm brakes, the program stops, the arm powers off once at rest."""
        self._hook("emergency_stop")

    def release_emergency_stop(self) -> None:
        """Release the button; the arm stays powered off until the dashboard powers it on and releases the brakes."""
        self._hook("release_emergency_stop")

    def unlock_protective_stop(self) -> str:
        """What the pendant's "unlock" does (the dashboard's ``unlock protective stop``); returns PolyScope's reply."""
        return str(self._hook("unlock_protective_stop")["reply"])

    def power_on(self) -> str:
        """Power the arm on and release the brakes (the pendant's "ON" then "START"); returns the reply."""
        return str(self._hook("power_on")["reply"])

    def trigger_protective_stop(self, why: str = "test hook") -> None:
        """Inject a protective stop (as if a safety limit tripped)."""
        self._hook("protective_stop", why=why)

    def set_placement_error(self, dx_m: float, dy_m: float) -> None:
        """Move the object by (dx, dy) m from where the rig file says it stands (the controller's scene only)."""
        self._hook("placement_error", error_m=[dx_m, dy_m])

    def set_disc_pad(self, radius_mm: float | None) -> None:
        """The pad as a disc of ``radius_mm`` against the object's circumscribed cylinder (10 N/mm, sim/scene_disc.py:
        an object to the side meets the rim, a contact force off the press axis); None: the press scene again."""
        self._hook("disc_pad", radius_mm=radius_mm)

    def set_contact_scale(self, scale: float) -> None:
        """Scale every contact force the controller's scene answers (10: a ten times stiffer object; 0.1: softer)."""
        self._hook("contact_scale", scale=scale)

    def set_ft_sign(self, sign: float) -> None:
        """-1: the wrist F/T reports (and force mode regulates on) the negated wrench: a flipped sensor frame."""
        self._hook("ft_sign", sign=sign)

    def set_remote_control(self, on: bool) -> None:
        """Pendant in Remote Control (True) or Local mode (False: clients refused, uploads ignored)."""
        self._hook("remote_control", on=on)

    def set_pendant_tcp(self, pose: np.ndarray | tuple[float, ...]) -> None:
        """Set the active TCP as an operator would on the pendant (m, rad)."""
        self._hook("pendant_tcp", pose=[float(v) for v in pose])

    def status(self) -> dict[str, Any]:
        """Program state, last error (a refused upload, a runtime error, why the program stopped), TCP, payload."""
        return self._hook("status")

    # ---- lifetime -------------------------------------------------------------------------------------------

    @property
    def alive(self) -> bool:
        return not self._closed and self._process.poll() is None

    def close(self) -> None:
        """Stop the controller process (its sockets close with it). Idempotent."""
        if self._closed:
            return
        self._shut_down()

    def _shut_down(self) -> None:
        """Close the process's stdin (EOF is its signal to stop), wait for it, kill it if it does not stop."""
        self._closed = True
        process = self._process
        if process.stdin is not None:
            with contextlib.suppress(OSError):
                process.stdin.close()
        try:
            process.wait(timeout=_STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:  # pragma: no cover - the controller polls stdin at least every 50 ms
            logger.warning("controller twin process did not stop; killing it")
            process.kill()
            process.wait(timeout=_STOP_TIMEOUT_S)
        if process.stdout is not None:
            process.stdout.close()
        self._truth.close()
        self._file.close()

    def __enter__(self) -> ControllerTwin:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


def address_free(host: str) -> bool:
    """Whether none of the controller ports is bound on ``host`` (TIME_WAIT is no obstacle, as for the twin)."""
    for port in CONTROLLER_PORTS:
        probe = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((host, port))
        except OSError:
            return False
        finally:
            probe.close()
    return True


def _free_loopbacks(first: int, last: int) -> Iterator[str]:
    """Each 127.0.0.x (``first`` <= x <= ``last``) where no controller port is bound, checked as it is reached."""
    for octet in range(first, last + 1):
        host = f"127.0.0.{octet}"
        if address_free(host):
            yield host


def _no_free_loopback(first: int, last: int) -> DeviceError:
    return DeviceError(
        f"no free loopback address for a controller twin in 127.0.0.{first}-{last}",
        hint="close other controller twins or URSim instances",
    )


def first_free_loopback(first: int, last: int = 254) -> str:
    """The first 127.0.0.x (``first`` <= x <= ``last``) where no controller port is bound, for a twin to take."""
    for host in _free_loopbacks(first, last):
        return host
    raise _no_free_loopback(first, last)


def start_twin_on_free_loopback(first: int, last: int = 254, **kwargs: Any) -> ControllerTwin:
    """A :class:`ControllerTwin` on the first 127.0.0.x (``first`` <= x <= ``last``) whose ports are all free."""
    for host in _free_loopbacks(first, last):
        try:
            return ControllerTwin(host, **kwargs)
        except AddressTaken:
            continue  # taken between the check and the start
    raise _no_free_loopback(first, last)

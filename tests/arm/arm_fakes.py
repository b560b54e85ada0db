"""Fakes for the arm tests: a linear-spring world, and stand-ins for ur_rtde's control and receive objects."""

from __future__ import annotations

import numpy as np
import rtde_control

from drivers.clock import VirtualClock
from unitac_rig.sim.arm import SimArm, SimArmParams

PRESS_DIR = np.array([0.0, 1.0, 0.0])  # press along base +y
START_POSE = np.array([0.0, 0.0, 0.2, 0.0, 0.0, 0.0])

# A sensor with no noise, bias, drift or filter: only the latency is left, so results can be worked by hand.
EXACT_FT = SimArmParams(
    ft_noise_sigma_n=0.0,
    ft_bias_sigma_n=0.0,
    ft_bias_drift_n_per_sqrt_s=0.0,
    ft_filter_cutoff_hz=None,
    ft_latency_s=0.010,
)


class SpringWorld:
    """A flat wall normal to ``direction``: force = stiffness x penetration past ``contact_m`` along it, else 0."""

    def __init__(self, stiffness_n_m: float, contact_m: float, direction: np.ndarray = PRESS_DIR) -> None:
        self.stiffness_n_m = stiffness_n_m
        self.contact_m = contact_m
        self.direction = direction

    def wrench_on_tool(self, tcp_pose: np.ndarray) -> np.ndarray:
        penetration = float(np.dot(tcp_pose[:3] - START_POSE[:3], self.direction)) - self.contact_m
        wrench = np.zeros(6)
        wrench[:3] = -self.stiffness_n_m * max(0.0, penetration) * self.direction
        return wrench


def make_arm(world: SpringWorld, params: SimArmParams = EXACT_FT, seed: int = 0) -> SimArm:
    return SimArm(world, clock=VirtualClock(), rng=np.random.default_rng(seed), params=params, start_pose=START_POSE)


class FakeControl:
    """Records every command like a flight recorder; ``results`` sets what a method returns (True by default).

    It stays only where the controller twin cannot reach: exact argument order, and a client that raises or refuses
    on cue. Queries (isProgramRunning, getAsyncOperationProgressEx, getTCPOffset) are answered, not recorded.
    An asynchronous moveL shows as running for ``move_periods`` reads of the progress word, then as finished.
    """

    def __init__(self, **results: object) -> None:
        self.calls: list[tuple[str, tuple[object, ...]]] = []
        self.results = results
        self.raise_on: dict[str, BaseException] = {}
        self.period_starts = 0
        self.program_running = True
        self.tcp_offset = [0.0, 0.0, 0.1, 0.0, 0.0, 0.0]
        self.operation = 0  # the async operation id of the progress word
        self.stale_words: list[int] = []  # progress words returned first, before the current state
        self.move_periods = 3
        self._move_reads_left = 0

    def names(self) -> list[str]:
        return [name for name, _ in self.calls]

    def commands(self) -> list[str]:
        """Recorded names without the watchdog kicks and period waits."""
        return [name for name in self.names() if name not in ("kickWatchdog", "waitPeriod")]

    def _record(self, name: str, *args: object) -> object:
        self.calls.append((name, args))
        if name in self.raise_on:
            raise self.raise_on[name]
        return self.results.get(name, True)

    def moveL(self, pose: list[float], speed: float, acceleration: float, asynchronous: bool) -> object:
        result = self._record("moveL", pose, speed, acceleration, asynchronous)
        if result is not False and asynchronous:
            self.operation = (self.operation + 1) % 128
            self._move_reads_left = self.move_periods
        return result

    def getAsyncOperationProgressEx(self) -> rtde_control.AsyncOperationStatus:
        """The script's word: operation id in bits 24-30 (one more at each asynchronous start), bit 15 running."""
        if self.stale_words:  # what the control client's stream still showed from before
            return rtde_control.AsyncOperationStatus(self.stale_words.pop(0))
        running = self._move_reads_left > 0
        if running:
            self._move_reads_left -= 1
        return rtde_control.AsyncOperationStatus((self.operation << 24) | (0x8000 if running else 0))

    def stop_moves(self) -> None:
        """The controller's move thread ends (test hook)."""
        self._move_reads_left = 0

    def stopL(self, a: float, asynchronous: bool) -> object:
        self._move_reads_left = 0
        return self._record("stopL", a, asynchronous)

    def speedL(self, xd: list[float], acceleration: float, time: float) -> object:
        return self._record("speedL", xd, acceleration, time)

    def speedStop(self, a: float) -> object:
        return self._record("speedStop", a)

    def zeroFtSensor(self) -> object:
        return self._record("zeroFtSensor")

    def forceMode(self, *args: object) -> object:
        return self._record("forceMode", *args)

    def forceModeStop(self) -> object:
        return self._record("forceModeStop")

    def setWatchdog(self, min_frequency: float) -> object:
        return self._record("setWatchdog", min_frequency)

    def kickWatchdog(self) -> object:
        return self._record("kickWatchdog")

    def isProgramRunning(self) -> bool:
        return self.program_running

    def getTCPOffset(self) -> list[float]:
        return list(self.tcp_offset)

    def stopScript(self) -> None:
        self._record("stopScript")

    def disconnect(self) -> None:
        self._record("disconnect")

    def initPeriod(self) -> int:
        self.period_starts += 1
        return self.period_starts

    def waitPeriod(self, start: int) -> None:
        self._record("waitPeriod", start)


class FakeReceive:
    """RTDEReceiveInterface stand-in whose values a test sets directly."""

    def __init__(self) -> None:
        self.timestamp = 1.0
        self.pose = [0.1, 0.2, 0.3, 0.0, 0.0, 0.0]
        self.force = [0.0] * 6
        self.protective = False
        self.emergency = False
        self.connected = True
        self.disconnects = 0
        self.payload = 0.0

    def isConnected(self) -> bool:
        return self.connected

    def getTimestamp(self) -> float:
        self.timestamp += 0.002  # a fresh package every read
        return self.timestamp

    def getActualTCPPose(self) -> list[float]:
        return list(self.pose)

    def getActualTCPForce(self) -> list[float]:
        return list(self.force)

    def getActualTCPSpeed(self) -> list[float]:
        return [0.0] * 6

    def getRobotMode(self) -> int:
        return 7

    def getSafetyMode(self) -> int:
        return 3 if self.protective else 1

    def isProtectiveStopped(self) -> bool:
        return self.protective

    def isEmergencyStopped(self) -> bool:
        return self.emergency

    def getPayload(self) -> float:
        return self.payload

    def disconnect(self) -> None:
        self.disconnects += 1

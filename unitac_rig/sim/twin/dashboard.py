"""The dashboard server's command language (TCP 29999): one line in, one line out.

The replies follow PolyScope 5's dashboard server as ur_rtde's ``DashboardClient`` expects them (it strips the
trailing newline and compares whole strings, e.g. ``unlockProtectiveStop`` insists on ``Protective stop
releasing``). The controller state changes go through a :class:`DashboardHost`.
"""

from __future__ import annotations

import logging
from typing import Protocol

from unitac_rig.sim.twin.params import ControllerParams

logger = logging.getLogger(__name__)

WELCOME = "Connected: Universal Robots Dashboard Server"
UNLOCK_TOO_EARLY = (
    "Cannot unlock protective stop until 5s after occurrence. Always inspect cause of protective stop before unlocking"
)

# RTDE robot_mode and safety_mode numbers as the dashboard names them
ROBOT_MODE_NAMES = {
    -1: "NO_CONTROLLER",
    0: "DISCONNECTED",
    1: "CONFIRM_SAFETY",
    2: "BOOTING",
    3: "POWER_OFF",
    4: "POWER_ON",
    5: "IDLE",
    6: "BACKDRIVE",
    7: "RUNNING",
    8: "UPDATING_FIRMWARE",
}
SAFETY_MODE_NAMES = {
    1: "NORMAL",
    2: "REDUCED",
    3: "PROTECTIVE_STOP",
    4: "RECOVERY",
    5: "SAFEGUARD_STOP",
    6: "SYSTEM_EMERGENCY_STOP",
    7: "ROBOT_EMERGENCY_STOP",
    8: "VIOLATION",
    9: "FAULT",
}


class DashboardHost(Protocol):
    """The controller as the dashboard sees it."""

    params: ControllerParams
    remote_control: bool
    robot_mode: int

    def safety_mode(self) -> int: ...
    def program_state(self) -> str: ...
    def program_running(self) -> bool: ...
    def power_on(self) -> bool: ...
    def power_off(self) -> None: ...
    def brake_release(self) -> bool: ...
    def unlock_protective_stop(self) -> str: ...
    def stop_program(self, why: str) -> bool: ...
    def pause_program(self) -> bool: ...
    def play_program(self) -> bool: ...
    def restart_safety(self) -> None: ...


def answer(host: DashboardHost, line: str) -> tuple[str, bool]:
    """The reply to one command line, and whether the server closes the connection after it (``quit``)."""
    command = line.strip()
    lower = command.lower()
    if lower == "quit":
        return "Disconnected", True
    polyscope = f"URSoftware {host.params.polyscope_version} (Mar 03 2021)"
    if lower == "polyscopeversion":
        return polyscope, False
    if lower == "version":
        return f"Version information: {polyscope}", False
    if lower == "get serial number":
        return host.params.serial_number, False
    if lower == "get robot model":
        return host.params.robot_model, False
    if lower == "is in remote control":
        return "true" if host.remote_control else "false", False
    if lower == "robotmode":
        return f"Robotmode: {ROBOT_MODE_NAMES.get(host.robot_mode, 'UNKNOWN')}", False
    if lower == "safetymode":
        return f"Safetymode: {SAFETY_MODE_NAMES.get(host.safety_mode(), 'UNKNOWN')}", False
    if lower == "safetystatus":
        return f"Safetystatus: {SAFETY_MODE_NAMES.get(host.safety_mode(), 'UNKNOWN')}", False
    if lower == "programstate":
        return host.program_state(), False
    if lower == "running":
        return f"Program running: {'true' if host.program_running() else 'false'}", False
    if lower == "power on":
        return ("Powering on" if host.power_on() else "Failed to execute: power on"), False
    if lower == "power off":
        host.power_off()
        return "Powering off", False
    if lower == "brake release":
        return ("Brake releasing" if host.brake_release() else "Failed to execute: brake release"), False
    if lower == "unlock protective stop":
        return host.unlock_protective_stop(), False
    if lower == "close safety popup":
        return "closing safety popup", False
    if lower.startswith("popup "):
        logger.info("dashboard popup: %s", command[6:])
        return "showing popup", False
    if lower == "close popup":
        return "closing popup", False
    if lower == "stop":
        # ur_rtde's reuploadScript sends stopScript, then "stop", and throws unless the reply is "Stopped": a
        # controller answers so even when the program has just ended
        host.stop_program("dashboard stop")
        return "Stopped", False
    if lower == "pause":
        return ("Pausing program" if host.pause_program() else "Failed to execute: pause"), False
    if lower == "play":
        return ("Starting program" if host.play_program() else "Failed to execute: play"), False
    if lower == "restart safety":
        host.restart_safety()
        return "Restarting safety", False
    if lower == "get loaded program":
        return "No program loaded", False
    if lower.startswith("load "):
        return f"File not found: {command[5:]}", False
    if lower == "get operational mode":
        return "NONE", False
    if lower == "is program saved":
        return "true", False
    if lower.startswith("addtolog "):
        logger.info("dashboard log: %s", command[9:])
        return "Added log message", False
    return f"could not understand: '{command}'", False

"""The controller twin's process: ``python -m unitac_rig.sim.twin.process``, started by
:class:`unitac_rig.sim.twin.ControllerTwin`. It reads the settings as one JSON line on stdin, opens the ground-truth
block on the inherited ``--truth-fd``, asks for real-time scheduling, binds the controller's ports (printing
``ready`` or ``error ERRNO TEXT``) and runs :class:`~unitac_rig.sim.twin.controller.Controller` until stdin closes;
further stdin lines are test hooks."""

from __future__ import annotations

import logging
import os
import signal
import sys
from collections.abc import Sequence

from unitac_rig.sim.twin.controller import Controller
from unitac_rig.sim.twin.params import TwinSettings
from unitac_rig.sim.twin.truth import TruthBlock


def _raise_priority() -> str:
    """Ask for real-time scheduling as a controller has it; say what was granted (never fails)."""
    if hasattr(os, "sched_setscheduler"):
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))
            return "SCHED_FIFO 10"
        except (PermissionError, OSError):
            pass
    try:
        os.nice(-10)
        return "nice -10"
    except (PermissionError, OSError):
        return "normal (no permission for more)"


def main(argv: Sequence[str] | None = None) -> int:
    """Process entry point: settings on the first stdin line, the truth block on ``--truth-fd``."""
    import argparse

    parser = argparse.ArgumentParser(prog="python -m unitac_rig.sim.twin.process")
    parser.add_argument("--truth-fd", type=int, required=True)
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=os.environ.get("UNITAC_TWIN_LOG", "WARNING").upper(),
        format="controller twin %(levelname)s %(name)s: %(message)s",
    )
    stdin_fd = sys.stdin.fileno()
    first = b""
    while not first.endswith(b"\n"):
        chunk = os.read(stdin_fd, 65536)
        if not chunk:
            return 1
        first += chunk
    line, _, extra = first.partition(b"\n")
    settings = TwinSettings.from_json(line.decode())
    truth = TruthBlock(args.truth_fd)
    scheduling = _raise_priority() if settings.params.realtime_priority else "normal (not asked)"
    sys.setswitchinterval(0.0005)  # the cycle gets the GIL back from the table-building thread within 0.5 ms
    controller = Controller(settings, truth, hooks_in=stdin_fd)
    controller.scheduling = scheduling
    try:
        controller.bind()
    except OSError as exc:
        print(f"error {exc.errno or 0} {exc.strerror or exc}", flush=True)  # noqa: T201 - the parent reads this
        return 1
    print("ready", flush=True)  # noqa: T201 - the parent reads this line
    if extra:
        controller._hook_bytes(extra)
    try:
        controller.run()
    finally:
        truth.close()
    return 0


if __name__ == "__main__":
    # Ctrl-C in a terminal reaches the whole process group: the controller stops only when its owner closes stdin
    # (or dies), as a robot controller does not stop because a host process was interrupted.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    sys.exit(main())

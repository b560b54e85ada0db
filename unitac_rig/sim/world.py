"""The seam between the simulated arm and the physical scene it presses into."""

from __future__ import annotations

from typing import Protocol

import numpy as np


class ContactWorld(Protocol):
    def wrench_on_tool(self, tcp_pose: np.ndarray) -> np.ndarray:
        """Quasi-static wrench the environment exerts on the tool at ``tcp_pose``.

        ``tcp_pose``: (6,) [x, y, z (m), rx, ry, rz (rad, rotation vector)] in the robot base frame; the TCP is the
        centre of the sensing surface, tool +z points out of the pad toward the object (the press direction).
        Returns (6,) [Fx, Fy, Fz (N), Tx, Ty, Tz (N*m)] in base-frame axes about the TCP. Pressing along tool +z
        therefore gives a force with a negative component along the press direction.

        A world may return the same read-only array again while the wrench is unchanged (the arm then skips its
        copy and its force-limit check); an array it returns read-only must never change afterwards.
        """
        ...


def read_only(values: np.ndarray) -> np.ndarray:
    """``values`` made read only (a world's answer that will not change, see :meth:`ContactWorld.wrench_on_tool`)."""
    values.flags.writeable = False
    return values


NO_WRENCH = read_only(np.zeros(6))  # N, N*m: what a world answers where nothing touches the tool


class FreeSpace:
    """A world with nothing in it (probe runs, motion-only dry runs)."""

    def wrench_on_tool(self, tcp_pose: np.ndarray) -> np.ndarray:
        return NO_WRENCH

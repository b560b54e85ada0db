"""Fixtures of the controller-twin tests (helpers in twin_helpers.py)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.twin.twin_helpers import CENTER_M, TwinClients, open_twin
from unitac_rig.sim.twin import ControllerParams, SceneSpec


@pytest.fixture(scope="module")
def clients() -> Iterator[TwinClients]:
    """One twin with circle_pla in front of a uSkin pad, and the three real clients, for a whole test module."""
    scene = SceneSpec("circle_pla", sensor="uskin", center_m=CENTER_M, seed=7)
    params = ControllerParams(unlock_delay_s=1.0, protective_stop_n=60.0)  # 1 s: room for a slow host
    twin = open_twin(params, scene=scene)
    rig = TwinClients(twin)
    try:
        rig.connect()
        yield rig
    finally:
        try:
            rig.disconnect()
        finally:
            twin.close()


@pytest.fixture
def rig(clients: TwinClients) -> TwinClients:
    """The module's twin and clients, recovered to the known state before the test."""
    clients.recover()
    return clients

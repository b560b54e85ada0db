"""A press strategy added through the seam alone: defined in this module, registered with one line, chosen from a
rig file, pressing on the simulated rig; and whatever force it asks for, the press's limits still bound it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from unitac_rig.collection.safety_check import TickInfo
from unitac_rig.collection.session import collect_session
from unitac_rig.collection.strategy import PressContext
from unitac_rig.errors import ConfigError, SafetyLimit
from unitac_rig.rig.config import RigConfig, load_rig_config
from unitac_rig.rig.objects import get_object
from unitac_rig.rig.strategies import PRESS_STRATEGIES
from unitac_rig.sim.fast_rig import SimRig
from unitac_rig.storage.reader import read_presses
from unitac_rig.storage.recorder import session_path

HARD_LIMIT_N = 50.0  # far above the 10 N threshold: what stops an overreaching strategy must be the set-point


class Overreach:
    """Fast to first contact, then on at the slow speed until 40 N: four times the press threshold."""

    def press(self, ctx: PressContext) -> str:
        ctx.phase = "approach"
        first = ctx.move(ctx.press.fast_speed_mm_s, ctx.contact_threshold_n, keep_moving=True)
        if first.reason != "force":
            return first.reason
        ctx.phase = "press"
        return ctx.move(ctx.press.speed_mm_s, 40.0, samples=ctx.press.stop_samples).reason


class ForceHog:
    """Fast to first contact, then force control asking for 500 N for one second."""

    def press(self, ctx: PressContext) -> str:
        ctx.phase = "approach"
        first = ctx.move(ctx.press.fast_speed_mm_s, ctx.contact_threshold_n)
        if first.reason != "force":
            return first.reason
        ctx.phase = "press"
        for _ in range(round(1.0 / ctx.control_period_s)):
            ctx.force_control(500.0, ctx.press.speed_mm_s)
        return "force"


class PastTheLimit:
    """Asks to press until 10 N above the hard limit."""

    def press(self, ctx: PressContext) -> str:
        return ctx.move(ctx.press.speed_mm_s, ctx.limits.hard_force_n + 10.0).reason


OVERREACH, FORCE_HOG, PAST_THE_LIMIT = Overreach(), ForceHog(), PastTheLimit()


def _rig_file(tmp_path: Path, strategy: str) -> Path:
    path = tmp_path / "rig.toml"
    path.write_text(f'[press]\nstrategy = "{strategy}"\nangle_count = 1\n\n[limits]\nhard_force_n = {HARD_LIMIT_N}\n')
    return path


def _press_once(config: RigConfig, data: Path) -> tuple[float, list[str]]:
    """One press of hex_pla with the PapillArray; -> (the true peak |F| on the pad, N; the phases ticked)."""
    peak, phases = [0.0], []
    with SimRig(config, seed=2) as rig:

        def on_tick(tick: TickInfo) -> None:
            peak[0] = max(peak[0], float(np.linalg.norm(rig.sim_arm.true_wrench()[:3])))
            phases.append(tick.phase)

        collect_session(rig, get_object("hex_pla"), "papillarray", data, on_tick=on_tick)
    return peak[0], phases


def _register(monkeypatch: pytest.MonkeyPatch, name: str, attribute: str) -> None:
    monkeypatch.setitem(PRESS_STRATEGIES, name, f"{__name__}:{attribute}")  # the registry line


def test_a_rig_file_may_name_only_a_registered_strategy(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    rig_file = _rig_file(tmp_path, "overreach")
    with pytest.raises(ConfigError, match=r"press\.strategy: unknown press strategy 'overreach'"):
        load_rig_config(rig_file)
    _register(monkeypatch, "overreach", "OVERREACH")
    assert load_rig_config(rig_file).press.strategy == "overreach"


@pytest.mark.parametrize(("name", "attribute"), [("overreach", "OVERREACH"), ("force-hog", "FORCE_HOG")])
def test_a_new_strategy_presses_but_cannot_push_past_the_set_point(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, name: str, attribute: str
) -> None:
    """Asked for 40 N or 500 N, the pad feels what the press allows: the threshold + press.setpoint_margin_n
    (10.2 N) that the controller regulates toward, not what the strategy asked for; the press is recorded."""
    _register(monkeypatch, name, attribute)
    config = load_rig_config(_rig_file(tmp_path, name))
    peak_n, phases = _press_once(config, tmp_path / "data")
    (record,) = read_presses(session_path(tmp_path / "data", "hex_pla", "papillarray"))
    assert record.attrs["strategy"] == name
    assert {"approach", "press", "dwell", "retract"} <= set(phases)
    assert float(record.press_force_n.max()) > 8.0  # it did press
    assert peak_n < config.press.threshold_n + config.press.setpoint_margin_n + 1.5 < 40.0
    if name == "overreach":  # its 40 N was never reached: the move ran out of time at the set-point
        assert (record.status, record.reason) == ("failed", "timeout")


def test_a_strategy_asking_past_the_hard_limit_is_refused_before_it_moves(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _register(monkeypatch, "past-the-limit", "PAST_THE_LIMIT")
    config = load_rig_config(_rig_file(tmp_path, "past-the-limit"))
    with pytest.raises(SafetyLimit, match="at or above the hard limit 50 N"):
        _press_once(config, tmp_path / "data")
    (record,) = read_presses(session_path(tmp_path / "data", "hex_pla", "papillarray"))
    assert (record.status, record.reason) == ("aborted", "hard_limit")
    assert np.all(record.press_force_n < 2.0)  # the pad never touched the object

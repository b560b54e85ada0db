"""``force-ramp``: fast (``press.fast_speed_mm_s``) until first contact, then force control whose set-point rises at
``press.ramp_rate_n_s`` (N/s) until the measured force reaches the threshold (a slow force rise: a small
force-matching error)."""

from __future__ import annotations

import math

from unitac_rig.collection.strategy import PressContext

# Anti-windup: the set-point may lead the measured press force (mean of the last RAMP_MEAN_PERIODS control periods)
# by at most this, N. Without it a set-point ramping while nothing pushes back drives the admittance loop to its
# speed limit and the pad hits the object with the set-point already near the threshold.
RAMP_MAX_LEAD_N = 3.0
RAMP_MEAN_PERIODS = 10
RAMP_SPEED_FACTOR = 4.0  # force control may move at this times press.speed_mm_s
RAMP_EXTRA_S = 5.0  # the ramp may last threshold / rate plus this long, then the press fails ("travel")


class ForceRamp:
    def press(self, ctx: PressContext) -> str:
        press = ctx.press
        ctx.phase = "approach"
        first = ctx.move(press.fast_speed_mm_s, ctx.contact_threshold_n)
        if first.reason != "force":
            return first.reason
        ctx.phase = "press"
        return ramp(ctx)


def ramp(ctx: PressContext) -> str:
    """Force control along the press with a set-point rising at ``ramp_rate_n_s`` until the threshold is measured.

    The set-point is rate-limited from the force at the start and never leads the measured press force by more than
    ``RAMP_MAX_LEAD_N`` (while nothing pushes back the pad creeps at gain x lead instead of winding up to the speed
    limit) nor exceeds threshold + ``setpoint_margin_n`` (the context's cap too: the force a stalled host leaves the
    controller regulating toward).
    """
    press = ctx.press
    ceiling_n = press.threshold_n + press.setpoint_margin_n
    last = ctx.last_press_force_n
    setpoint = press.contact_force_n if last is None else last
    step_n = press.ramp_rate_n_s * ctx.control_period_s
    for _ in range(math.ceil((press.threshold_n / press.ramp_rate_n_s + RAMP_EXTRA_S) / ctx.control_period_s)):
        setpoint = min(setpoint + step_n, ctx.mean_press_force_n(RAMP_MEAN_PERIODS) + RAMP_MAX_LEAD_N, ceiling_n)
        ctx.force_control(setpoint, press.speed_mm_s * RAMP_SPEED_FACTOR)
        if ctx.mean_press_force_n(press.stop_samples) >= press.threshold_n:
            return "force"
    return "travel"


FORCE_RAMP = ForceRamp()

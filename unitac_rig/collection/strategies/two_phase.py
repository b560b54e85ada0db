"""``two-phase``: fast (``press.fast_speed_mm_s``) until first contact, then on at the slow ``press.speed_mm_s`` to
the threshold without stopping in between: shorter presses, the same final approach as ``guarded``. The default
(docs/benchmarks.md, "Press strategy")."""

from __future__ import annotations

from unitac_rig.collection.strategy import PressContext


class TwoPhase:
    def press(self, ctx: PressContext) -> str:
        press = ctx.press
        # fast to first contact (one reading over the contact threshold: a false alarm only makes the rest of the
        # approach slow), then straight on to the slow speed limit
        ctx.phase = "approach"
        first = ctx.move(press.fast_speed_mm_s, ctx.contact_threshold_n, keep_moving=True)
        if first.reason != "force":
            return first.reason
        ctx.phase = "press"
        # the rest of the travel budget (a false first-contact alarm far out must still reach the object)
        budget_m = max(ctx.backstop_m - first.travel_m, (ctx.limits.max_travel_after_contact_mm + 1.0) / 1000.0)
        return ctx.move(
            press.speed_mm_s, press.threshold_n, samples=press.stop_samples, travel_m=budget_m, final=True
        ).reason


TWO_PHASE = TwoPhase()

"""``guarded``: constant speed (``press.speed_mm_s``) from the stand-off until the press force reaches the threshold:
the paper's procedure, and the slowest."""

from __future__ import annotations

from unitac_rig.collection.strategy import PressContext


class Guarded:
    def press(self, ctx: PressContext) -> str:
        ctx.phase = "press"
        press = ctx.press
        return ctx.move(press.speed_mm_s, press.threshold_n, samples=press.stop_samples, final=True).reason


GUARDED = Guarded()

"""Pure wire codecs for the rig's devices: bytes or CAN messages in, typed messages out, and back.

No I/O, no threads, no clocks live here. Each codec module opens with a docstring stating its wire format and
where the facts come from. `drivers` builds on these; `unitac_rig.sim` uses the encoders to speak real bytes.
"""

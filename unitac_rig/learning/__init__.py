"""UniTac-NV learning: paired dataset, split, the multi-encoder/shared-decoder model and its baselines, training,
evaluation (NMAE, SSIM, latent alignment), reports, cross-sensor translation and downstream contact geometry.

Import the submodules you need (``unitac_rig.learning.train``, ``.translate``, ``.geometry``...); this package keeps
its import light so the CLI starts fast.
"""

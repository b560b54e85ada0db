"""The measuring code that only the ``benchmarks/*.py`` scripts (and the tests of that code) use.

It lives in the checkout, not in the wheel (``pyproject.toml`` excludes ``unitac_rig.bench.lab``): nothing in the
product imports it. What ``unitac-rig bench`` runs is one level up, in ``unitac_rig/bench/``.
"""

"""The measuring code the ``benchmarks/*.py`` scripts share (and the tests of that code import as ``lab``).

It lives in the checkout, outside the wheel: nothing in the product imports it. What ``unitac-rig bench`` runs is
``unitac_rig/bench/``.
"""

"""``python -m unitac_rig`` runs the CLI."""

from unitac_rig.cli import main

main()

"""``python -m unitac_rig`` runs the CLI."""

from unitac_rig.launch import main

main()

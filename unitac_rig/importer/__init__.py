"""Import the dataset the UniTac-NV authors published into this project's session files (see docs/import.md)."""

from unitac_rig.importer.conventions import (
    ExtractionConventions,
    ImportConventions,
    TactileMapping,
    conventions_from_dict,
    load_conventions,
)
from unitac_rig.importer.discovery import SourceFile, discover
from unitac_rig.importer.parsing import parse_number_column, read_processed_npz, read_raw_csv
from unitac_rig.importer.pipeline import FileReport, ImportReport, SessionReport, import_unitac_nv
from unitac_rig.importer.presses import approach_angle_deg, rotate_ft, segment_presses

__all__ = [
    "ExtractionConventions",
    "FileReport",
    "ImportConventions",
    "ImportReport",
    "SessionReport",
    "SourceFile",
    "TactileMapping",
    "approach_angle_deg",
    "conventions_from_dict",
    "discover",
    "import_unitac_nv",
    "load_conventions",
    "parse_number_column",
    "read_processed_npz",
    "read_raw_csv",
    "rotate_ft",
    "segment_presses",
]

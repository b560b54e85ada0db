"""``export``, ``verify`` and pooling: the Parquet holds exactly the matched frames, the manifest catches any changed
byte, several directories pool, and two different recordings of one session are refused."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from tests.helpers import cli
from tests.robustness.robustness_helpers import one_error_line, tree_hashes, write_synthetic_sessions
from unitac_rig.storage.export import export_dataset
from unitac_rig.storage.paired import build_paired_dataset, join_key
from unitac_rig.storage.reader import load_matched_set, load_matched_sets
from unitac_rig.storage.recorder import session_path


@pytest.fixture(scope="module")
def two_dirs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """Two dataset directories (as from two rigs or days), both sensors each: A holds circle_pla collected on the
    simulated rig (3 angles: real matching errors, provenance), B synthetic hex_tpu contacts (11 angles)."""
    root = tmp_path_factory.mktemp("pool")
    a, b = root / "A", root / "B"
    for _ in ("uskin", "papillarray"):  # the simulated rig mounts the next sensor without a complete session
        assert cli(["collect", "--object", "circle_pla", "--data", str(a), "--angles", "3", "--no-live"]) == 0
    write_synthetic_sessions(b, ("hex_tpu",))
    return a, b


@pytest.fixture(scope="module")
def exported(two_dirs: tuple[Path, Path], tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("exports") / "pooled"
    assert cli(["export", str(two_dirs[0]), str(two_dirs[1]), "--out", str(out)]) == 0
    return out


def test_parquet_read_with_pandas_holds_exactly_the_matched_frames(two_dirs: tuple[Path, Path], exported: Path) -> None:
    df = pd.read_parquet(exported / "pairs.parquet")
    sets = [*load_matched_sets(two_dirs[0]), *load_matched_sets(two_dirs[1])]
    paired = build_paired_dataset(sets)
    assert len(df) == 2 * len(paired) and set(df["sensor"]) == {"uskin", "papillarray"}
    assert set(df["object"]) == {"circle_pla", "hex_tpu"}
    # every row is the session's own matched frame, force and error for that (object, rotation, angle, target)
    by_key = {}
    for matched in sets:
        for i in range(len(matched)):
            key = join_key(matched.object_id, matched.rotation_deg[i], matched.angle_deg[i], matched.target_n[i])
            by_key[(*key, matched.sensor)] = (matched.values[i], matched.force_n[i], matched.error_n[i])
    for row in df.itertuples():
        frame, force, error = by_key[(*join_key(row.object, row.rotation_deg, row.angle_deg, row.target_n), row.sensor)]
        assert np.array_equal(np.stack(row.frame), frame)
        assert row.force_n == pytest.approx(force) and row.error_n == pytest.approx(error, abs=1e-9)
        assert row.session == f"raw/{row.object}__{row.sensor}.h5"
        assert row.frame_unit == {"uskin": "counts", "papillarray": "N"}[row.sensor]
    # the rows of one contact are one press at one target, seen by each sensor
    assert (df["error_n"] != 0).sum() > len(df) // 2  # the collected contacts carry real matching errors
    circle = df[df["object"] == "circle_pla"]
    assert set(circle["shape"]) == {"circle"} and set(circle["material"]) == {"PLA"}
    per_contact = df.groupby("contact").agg({"sensor": "nunique", "target_n": "nunique", "angle_deg": "nunique"})
    assert (per_contact["sensor"] == 2).all() and (per_contact[["target_n", "angle_deg"]] == 1).all().all()


def test_units_are_in_the_parquet_schema_and_the_manifest(exported: Path) -> None:
    schema = pq.read_schema(exported / "pairs.parquet")
    assert schema.field("force_n").metadata[b"unit"] == b"N"
    assert schema.field("angle_deg").metadata[b"unit"] == b"deg"
    meta = json.loads(schema.metadata[b"unitac_rig"])
    assert meta["sensors"]["uskin"]["units"] == "counts" and meta["sensors"]["papillarray"]["n_taxels"] == 9
    manifest = json.loads((exported / "manifest.json").read_text())
    assert manifest["units"]["target_n"] == "N"
    assert {c["name"] for c in manifest["schema"]} >= {"object", "rotation_deg", "angle_deg", "target_n", "force_n",
                                                        "error_n", "frame", "sensor"}  # fmt: skip
    assert (
        manifest["counts"]["rows"]
        == 2 * manifest["counts"]["contacts"]
        == len(pd.read_parquet(exported / "pairs.parquet"))
    )


def test_manifest_lists_every_file_with_its_sha256_and_every_session_with_provenance(
    two_dirs: tuple[Path, Path], exported: Path
) -> None:
    manifest = json.loads((exported / "manifest.json").read_text())
    on_disk = {rel for rel in tree_hashes(exported) if rel != "manifest.json"}
    listed = {f["path"]: f["sha256"] for f in manifest["files"]}
    assert set(listed) == on_disk
    assert all(listed[rel] == digest for rel, digest in tree_hashes(exported).items() if rel in listed)
    sessions = {(s["object"], s["sensor"]): s for s in manifest["sessions"]}
    assert set(sessions) == {(o, s) for o in ("circle_pla", "hex_tpu") for s in ("uskin", "papillarray")}
    source = session_path(two_dirs[0], "circle_pla", "uskin")
    raw = sessions[("circle_pla", "uskin")]
    assert raw["source"] == str(two_dirs[0]) and raw["file"] == "raw/circle_pla__uskin.h5"
    # the raw session stays HDF5, byte for byte the source
    assert raw["sha256"] == tree_hashes(source.parent)[source.name] == listed["raw/circle_pla__uskin.h5"]
    assert raw["presses"]["planned"] == 3 and raw["rig"] and raw["git_commit"] and raw["package_version"]
    assert raw["extraction_settings"]["tolerance_n"] > 0 and raw["being_collected_at_export"] is False
    assert sessions[("hex_tpu", "uskin")]["presses"] == {"planned": 11, "complete": 11, "failed": 0, "aborted": 0}
    card = (exported / "README.md").read_text()
    assert "pairs.parquet" in card and "circle_pla" in card and "Simulated" in card


def test_verify_passes_then_names_the_first_changed_file(
    exported: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    copy = tmp_path / "copy"
    shutil.copytree(exported, copy)
    assert cli(["verify", str(copy)]) == 0
    assert "ok: 6 files" in capsys.readouterr().out
    victim = copy / "raw" / "hex_tpu__papillarray.h5"
    data = bytearray(victim.read_bytes())
    data[len(data) // 2] ^= 0x01  # one flipped bit, same size
    victim.write_bytes(bytes(data))
    assert cli(["verify", str(copy)]) == 1
    line = one_error_line(capsys)
    assert "raw/hex_tpu__papillarray.h5" in line and "SHA-256" in line
    (copy / "pairs.parquet").unlink()
    assert cli(["verify", str(copy)]) == 1
    assert "pairs.parquet: listed in the manifest but missing" in one_error_line(capsys)


def test_verify_without_a_manifest_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli(["verify", str(tmp_path)]) == 1
    assert "manifest.json does not exist" in one_error_line(capsys)


def test_pooling_a_byte_identical_copy_counts_the_session_once(
    two_dirs: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mirror = tmp_path / "mirror"
    shutil.copytree(two_dirs[0], mirror)  # the same sessions, copied to another machine
    out = tmp_path / "out"
    assert cli(["export", str(two_dirs[0]), str(mirror), "--out", str(out)]) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    assert len(manifest["sessions"]) == 2
    assert all(s["also_in"] == [str(mirror)] for s in manifest["sessions"])
    assert len(pd.read_parquet(out / "pairs.parquet")) == 2 * len(build_paired_dataset(load_matched_sets(mirror)))


def test_the_export_pairs_by_itself_exactly_as_training_does(two_dirs: tuple[Path, Path], tmp_path: Path) -> None:
    """Storage owns the join: the library call needs no join passed in, and its pairs are the ones ``train`` reads
    (the learning side's ``build_paired_dataset`` is this very function, so the content hashes agree)."""
    from unitac_rig.learning import data

    summary = export_dataset([two_dirs[1]], tmp_path / "out")
    paired = data.build_paired_dataset(data.load_sets(two_dirs[1]))
    assert data.build_paired_dataset is build_paired_dataset
    manifest = json.loads((tmp_path / "out" / "manifest.json").read_text())
    assert manifest["paired_content_hash"] == paired.content_hash()
    assert summary.contacts == len(paired) and summary.sensors == ("uskin", "papillarray")


def test_two_sources_disagreeing_on_a_session_is_a_clear_error(
    two_dirs: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    other = tmp_path / "other_rig"  # another recording of the same session (another seed: other presses)
    assert cli(["collect", "--object", "circle_pla", "--sensor", "uskin", "--data", str(other), "--angles", "3",
                "--seed", "1", "--no-live"]) == 0  # fmt: skip
    out = tmp_path / "out"
    assert cli(["export", str(two_dirs[0]), str(other), "--out", str(out)]) == 1
    line = one_error_line(capsys)
    assert "two sources disagree on session circle_pla/uskin" in line
    assert str(two_dirs[0]) in line and str(other) in line
    assert not out.exists() and not list(tmp_path.glob(".out.partial-*"))  # nothing half-written left behind


def test_export_never_writes_into_a_directory_that_holds_files(
    two_dirs: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    before = tree_hashes(out)
    assert cli(["export", str(two_dirs[0]), "--out", str(out)]) == 2  # a usage error, like export-model's
    assert "already exists and is not an empty directory" in one_error_line(capsys)
    assert tree_hashes(out) == before


def test_one_sensor_only_cannot_be_paired(two_dirs: tuple[Path, Path], tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    solo = tmp_path / "solo"
    solo.mkdir()
    shutil.copy(session_path(two_dirs[0], "circle_pla", "uskin"), solo)
    assert cli(["export", str(solo), "--out", str(tmp_path / "out")]) == 1
    assert "only one sensor" in one_error_line(capsys)
    assert load_matched_set(solo / "circle_pla__uskin.h5").sensor == "uskin"

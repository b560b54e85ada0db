"""Opening a run never runs code from it: checkpoints load with weights_only=True, and a file that needs anything
beyond tensors and plain values is refused with one line that says what it is and what to do."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import torch

from tests.helpers import cli
from unitac_rig.errors import ModelError
from unitac_rig.learning.run import CHECKPOINT_FORMAT, checkpoint_path, load_checkpoint
from unitac_rig.learning.train import TrainConfig


class _RunsCode:
    """Unpickling this calls ``exec`` on a line that writes a marker file: what a hostile checkpoint would do."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self) -> tuple[object, tuple[str]]:
        return (exec, (f"open({str(self.marker)!r}, 'w').write('ran')",))


def _write(run: Path, payload: object) -> Path:
    run.mkdir(parents=True, exist_ok=True)
    torch.save(payload, checkpoint_path(run))
    return checkpoint_path(run)


def test_a_checkpoint_that_would_run_code_is_refused_without_running_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    marker = tmp_path / "marker.txt"
    path = _write(tmp_path / "run", {"format": CHECKPOINT_FORMAT, "version": 2, "config": _RunsCode(marker)})

    with pytest.raises(ModelError, match=r"builtins\.exec.*could run code") as caught:
        load_checkpoint(tmp_path / "run")
    assert "retrain" in caught.value.one_line()
    assert not marker.exists()

    frames = tmp_path / "frames.npy"
    np.save(frames, np.zeros((2, 24, 3), dtype=np.float32))
    assert cli(["translate", str(tmp_path / "run"), str(frames), "--from", "uskin", "--to", "papillarray"]) == 1
    err = capsys.readouterr().err
    assert "was not loaded" in err and len(err.strip().splitlines()) == 1
    assert not marker.exists()

    # the file really is hostile: the unsafe loader runs it (this is what weights_only=True prevents)
    torch.load(path, weights_only=False)
    assert marker.read_text() == "ran"


def test_a_checkpoint_with_pickled_objects_says_what_it_is(tmp_path: Path) -> None:
    # a file that pickles classes (here even our own training config) is not one this unitac-rig writes
    _write(tmp_path / "run", {"format": CHECKPOINT_FORMAT, "version": 3, "config": TrainConfig(epochs=2)})
    with pytest.raises(ModelError) as caught:
        load_checkpoint(tmp_path / "run")
    assert re.search(
        r"unitac_rig\.learning\.config\.TrainConfig, unitac_rig\.learning\.network\.ModelShape\)"
        r".*not one of this unitac-rig's files",
        caught.value.one_line(),
    )


def test_foreign_damaged_and_newer_files_are_one_clear_model_error(tmp_path: Path) -> None:
    _write(tmp_path / "state", {"layer.weight": torch.zeros(2, 2), "layer.bias": torch.zeros(2)})
    with pytest.raises(ModelError, match=r"not a unitac-rig UniTac-NV checkpoint \(a plain PyTorch state dict of 2"):
        load_checkpoint(tmp_path / "state")

    (tmp_path / "junk").mkdir()
    checkpoint_path(tmp_path / "junk").write_bytes(b"this is not a torch file")
    with pytest.raises(ModelError, match="not a PyTorch file or damaged"):
        load_checkpoint(tmp_path / "junk")

    _write(tmp_path / "newer", {"format": CHECKPOINT_FORMAT, "version": 99})
    with pytest.raises(ModelError, match="version 99; this unitac-rig reads version 3 only") as caught:
        load_checkpoint(tmp_path / "newer")
    assert "upgrade unitac-rig" in caught.value.one_line()

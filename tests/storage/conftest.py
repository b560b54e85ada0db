"""Fixtures the storage tests share: a small recorded dataset, pristine per module and copied per test."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from tests.robustness.robustness_helpers import write_synthetic_sessions


@pytest.fixture(scope="module")
def pristine(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Both sensors on two objects (synthetic contacts through the real recorder): enough to train on."""
    data = tmp_path_factory.mktemp("pristine") / "data"
    write_synthetic_sessions(data)
    return data


@pytest.fixture
def data(pristine: Path, tmp_path: Path) -> Path:
    """A copy of ``pristine`` the test may damage."""
    copy = tmp_path / "data"
    shutil.copytree(pristine, copy)
    return copy

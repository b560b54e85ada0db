"""The training benchmark compares like with like: its three trainers (the stacked model, torch.func vmap and the plain
loop over the member networks sliced out of it) start from the same weights and take the same steps."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
import torch

from bench_training import TRAINERS, build_step
from unitac_rig.learning.engine import ModelShape

DIMS = {"uskin": 72, "papillarray": 27}


@pytest.fixture(autouse=True, scope="module")
def one_thread() -> Iterator[None]:
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(previous)


@pytest.mark.parametrize("size", [1, 15])
def test_every_trainer_takes_the_same_steps_without_dropout(size: int) -> None:
    # 64 rows = one batch per epoch, so every trainer sees the same rows whatever its shuffling (the MAE ignores order)
    x = torch.randn(64, 99, generator=torch.Generator().manual_seed(0))
    steps = {trainer: build_step(trainer, x, DIMS, size, ModelShape(dropout=0.0)) for trainer in TRAINERS}
    losses = {trainer: [float(step()) for _ in range(3)] for trainer, step in steps.items()}
    for trainer in TRAINERS:
        assert losses[trainer] == pytest.approx(losses["autograd"], rel=1e-5), trainer
    assert losses["autograd"][2] < losses["autograd"][0]  # the steps train


def test_a_stack_is_one_model_or_whole_seeds() -> None:
    with pytest.raises(ValueError, match="multiple of 3"):
        build_step("autograd", torch.zeros(64, 99), DIMS, 4, ModelShape())

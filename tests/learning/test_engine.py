"""The hand-written batched engine computes what the textbook nn.Module + autograd computes."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from unitac_rig.learning.engine import ModelShape, StackedAutoencoders, default_groups
from unitac_rig.learning.reference import UniTacModule

THREE_SENSORS = {"uskin": 72, "papillarray": 27, "fakepad": 12}


def linears(module: torch.nn.Module) -> list[torch.nn.Linear]:
    return [m for m in module.modules() if isinstance(m, torch.nn.Linear)]


@pytest.mark.parametrize("feature_dims", [{"uskin": 72, "papillarray": 27}, THREE_SENSORS])
def test_loss_and_every_gradient_match_autograd(feature_dims: dict[str, int]) -> None:
    shape = ModelShape(dropout=0.0)
    engine = StackedAutoencoders(feature_dims, default_groups(list(feature_dims), False), [7], shape)
    module = UniTacModule(feature_dims, shape)
    module.load_from_engine(engine, 0)
    batch = torch.randn(64, sum(feature_dims.values()), generator=torch.Generator().manual_seed(1))
    inputs = list(torch.split(batch, list(feature_dims.values()), dim=1))

    frozen = torch.optim.SGD([engine.theta], lr=0.0)  # computes grads, changes nothing
    loss = engine.train_step(batch.unsqueeze(0), frozen)
    reference = module.loss(inputs)
    reference.backward()
    assert float(loss[0, 0]) == pytest.approx(float(reference.detach()), rel=1e-5)

    grads = StackedAutoencoders(feature_dims, engine.groups, [7], shape, initialise=False)
    grads.theta.copy_(engine.grad)
    ours = grads.layer_parameters("unitac", 0)
    for sensor in feature_dims:
        for i, layer in enumerate(linears(module.encoders[sensor])):
            assert layer.weight.grad is not None and layer.bias.grad is not None
            np.testing.assert_allclose(ours[f"enc_{sensor}/{i}"][0], layer.weight.grad.T.numpy(), rtol=1e-4, atol=1e-7)
            np.testing.assert_allclose(ours[f"enc_{sensor}/{i}"][1], layer.bias.grad.numpy(), rtol=1e-4, atol=1e-7)
    for i, layer in enumerate(linears(module.decoder)):
        assert layer.weight.grad is not None
        np.testing.assert_allclose(ours[f"dec/{i}"][0], layer.weight.grad.T.numpy(), rtol=1e-4, atol=1e-7)


def test_inference_matches_the_module_in_eval_mode() -> None:
    dims = {"uskin": 72, "papillarray": 27}
    engine = StackedAutoencoders(dims, default_groups(list(dims), True), [0, 1], ModelShape())
    module = UniTacModule(dims, ModelShape())
    module.load_from_engine(engine, 1)
    module.eval()
    x = torch.randn(5, 27)
    z = engine.encode("unitac", "papillarray", x)
    assert z.shape == (2, 5, 16)
    decoded = engine.decode("unitac", z)
    expected = module.decoder(module.encoders["papillarray"](x))
    np.testing.assert_allclose(decoded["uskin"][1].numpy(), expected[:, :72].detach().numpy(), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(
        decoded["papillarray"][1].numpy(), expected[:, 72:].detach().numpy(), rtol=1e-5, atol=1e-6
    )
    # a baseline has its own encoder and a decoder for its sensor only
    assert set(engine.decode("ae_uskin", engine.encode("ae_uskin", "uskin", torch.randn(3, 72)))) == {"uskin"}


def test_dropout_drops_the_asked_fraction_and_rescales_the_rest() -> None:
    engine = StackedAutoencoders({"a": 6, "b": 3}, default_groups(["a", "b"], False), [0, 1], ModelShape(dropout=0.2))
    masks = engine._draw_masks(64)
    assert masks is not None
    values = torch.cat([m.reshape(-1) for m in masks.values()])
    dropped = float((values == 0).float().mean())
    assert dropped == pytest.approx(0.2, abs=0.01)  # ~100k mask entries: binomial sd ~0.0013
    assert torch.allclose(values[values != 0], torch.tensor(1 / 0.8))
    member0, member1 = (torch.cat([m[i].reshape(-1) for m in masks.values()]) for i in range(2))
    assert not torch.equal(member0, member1)  # each member has its own stream


def test_members_are_independent_and_state_round_trips() -> None:
    dims = {"a": 9, "b": 6}
    together = StackedAutoencoders(dims, default_groups(["a", "b"], True), [3, 4], ModelShape())
    alone = StackedAutoencoders(dims, default_groups(["a", "b"], True), [4], ModelShape())
    assert torch.equal(together.member(1).theta, alone.theta)  # seed 4 starts the same wherever it sits
    data = torch.randn(256, 15, generator=torch.Generator().manual_seed(0))
    opt_t, opt_a = together.make_optimizer(1e-3), alone.make_optimizer(1e-3)
    for start in range(0, 256, 64):
        together.train_step(data[start : start + 64].unsqueeze(0).expand(2, -1, -1).contiguous(), opt_t)
        alone.train_step(data[start : start + 64].unsqueeze(0), opt_a)
    torch.testing.assert_close(together.member(1).theta, alone.theta, rtol=1e-5, atol=1e-6)
    restored = StackedAutoencoders.from_state(together.state())
    assert torch.equal(restored.theta, together.theta)


def test_training_lowers_the_loss_on_a_learnable_pairing() -> None:
    generator = torch.Generator().manual_seed(0)
    hidden = torch.randn(512, 3, generator=generator)  # both "sensors" see the same 3 causes
    a = hidden @ torch.randn(3, 12, generator=generator)
    b = torch.tanh(hidden @ torch.randn(3, 6, generator=generator))
    data = torch.cat([a, b], dim=1)
    engine = StackedAutoencoders({"a": 12, "b": 6}, default_groups(["a", "b"], False), [0], ModelShape())
    optimizer = engine.make_optimizer(5e-3)
    first = float(engine.train_step(data[:64].unsqueeze(0), optimizer)[0, 0])
    for _ in range(20):
        for start in range(0, 512, 64):
            last = float(engine.train_step(data[start : start + 64].unsqueeze(0), optimizer)[0, 0])
    assert last < 0.5 * first

"""The stacked model computes what each member's plain network computes: the same losses and the same gradient for
every parameter of every model and seed, with dropout on; a member sliced out is that plain network."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
import torch
from torch import nn

from unitac_rig.errors import ModelError
from unitac_rig.learning.engine import Autoencoder, GroupSpec, ModelShape, StackedAutoencoders, default_groups

TWO_SENSORS = {"uskin": 72, "papillarray": 27}
THREE_SENSORS = {"uskin": 72, "papillarray": 27, "fakepad": 12}
SEEDS = [3, 5, 8]
ROWS = 64


@pytest.fixture(autouse=True, scope="module")
def one_thread() -> Iterator[None]:
    """Train as `unitac-rig train` does on a CPU: one thread (a second one only waits on a loaded 2-core box)."""
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(previous)


def run_with_masks(mlp: nn.Sequential, h: torch.Tensor, masks: list[torch.Tensor]) -> torch.Tensor:
    """``mlp(h)`` with its ``nn.Dropout`` modules, in order, replaced by the stacked model's masks (0 dropped,
    1/(1-p) kept): the plain network must have a dropout exactly where the stacked one drew a mask."""
    left = list(masks)
    for module in mlp:
        h = h * left.pop(0) if isinstance(module, nn.Dropout) else module(h)
    assert not left, "a mask with no nn.Dropout in the plain network"
    return h


def plain_loss(
    net: Autoencoder, inputs: list[torch.Tensor], masks: dict[str, torch.Tensor], group: GroupSpec, member: int
) -> torch.Tensor:
    """The member's loss written the textbook way on its plain network: each source encoded and decoded on its own
    (the stacked model decodes every source's latent in one batch: rows of source 0, then source 1, ...), one
    ``l1_loss`` per (source, target)."""
    mine = {key.split("/", 1)[1]: mask[member] for key, mask in masks.items() if key.startswith(group.name + "/")}
    total = torch.zeros(())
    for j, (source, x) in enumerate(zip(group.sensors, inputs, strict=True)):
        z = run_with_masks(net.encoders[source], x, [v for k, v in mine.items() if k.startswith(f"enc_{source}/")])
        dec = [v[j * ROWS : (j + 1) * ROWS] for k, v in mine.items() if k.startswith("dec/")]
        h = run_with_masks(net.decoder, z, dec)
        recon = torch.cat([head(h) for head in net.heads], dim=-1)
        for target, estimate in zip(inputs, recon.split([t.shape[1] for t in inputs], dim=-1), strict=True):
            total = total + nn.functional.l1_loss(estimate, target)
    return total


@pytest.mark.parametrize("dropout", [0.007, 0.2])
@pytest.mark.parametrize("feature_dims", [TWO_SENSORS, THREE_SENSORS], ids=["2 sensors", "3 sensors"])
def test_every_gradient_matches_independent_modules_with_dropout_seeds_and_baselines(
    feature_dims: dict[str, int], dropout: float
) -> None:
    shape = ModelShape(dropout=dropout)
    engine = StackedAutoencoders(feature_dims, default_groups(list(feature_dims), True), SEEDS, shape)
    batch = torch.randn(len(SEEDS), ROWS, sum(feature_dims.values()), generator=torch.Generator().manual_seed(1))
    masks = engine.draw_masks(ROWS)
    assert masks is not None
    dropped = {key: int((mask == 0).sum()) for key, mask in masks.items()}
    assert sum(dropped.values()) > 0
    if dropout >= 0.2:  # every layer's mask, the latent's included, really drops units here
        assert min(dropped.values()) > 0

    frozen = torch.optim.SGD(engine.parameters(), lr=0.0)  # computes gradients, changes nothing
    losses = engine.train_step(batch, frozen, masks=masks)

    per_sensor = torch.split(batch, list(feature_dims.values()), dim=-1)
    columns = dict(zip(feature_dims, per_sensor, strict=True))
    compared = 0
    for g, group in enumerate(engine.groups):
        for member in range(len(SEEDS)):
            net = engine.network(group.name, member)
            assert sum(isinstance(m, nn.Dropout) for m in net.modules()) == len(group.sensors) * 3 + 2
            inputs = [columns[s][member] for s in group.sensors]
            reference = plain_loss(net, inputs, masks, group, member)
            reference.backward()
            assert float(losses[g, member]) == pytest.approx(float(reference.detach()), rel=1e-5)

            ours = engine.layer_gradients(group.name, member)
            for key, layer in net.linears().items():
                assert layer.weight.grad is not None and layer.bias.grad is not None
                weight_grad, bias_grad = ours[key]
                torch.testing.assert_close(torch.from_numpy(weight_grad), layer.weight.grad.T, rtol=1e-4, atol=1e-7)
                torch.testing.assert_close(torch.from_numpy(bias_grad), layer.bias.grad, rtol=1e-4, atol=1e-7)
                compared += 2
    assert compared == len(SEEDS) * sum(2 * 3 * (len(g.sensors) + 1) for g in engine.groups)  # every tensor


def test_a_member_sliced_out_is_the_plain_network_in_eval_mode() -> None:
    engine = StackedAutoencoders(TWO_SENSORS, default_groups(list(TWO_SENSORS), True), [0, 1], ModelShape())
    module = engine.network("unitac", 1).eval()
    assert isinstance(module, nn.Module) and not isinstance(module, StackedAutoencoders)
    x = torch.randn(5, 27)
    z = engine.encode("unitac", "papillarray", x)
    assert z.shape == (2, 5, 16)
    decoded = engine.decode("unitac", z)
    expected = module.decode(module.encoders["papillarray"](x)).detach()
    torch.testing.assert_close(decoded["uskin"][1], expected[:, :72], rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(decoded["papillarray"][1], expected[:, 72:], rtol=1e-5, atol=1e-6)
    # a baseline has its own encoder and a decoder for its sensor only
    assert set(engine.decode("ae_uskin", engine.encode("ae_uskin", "uskin", torch.randn(3, 72)))) == {"uskin"}


def test_dropout_drops_the_asked_fraction_everywhere_and_rescales_the_rest() -> None:
    engine = StackedAutoencoders({"a": 6, "b": 3}, default_groups(["a", "b"], False), [0, 1], ModelShape(dropout=0.2))
    draws = []
    for _ in range(20):
        masks = engine.draw_masks(ROWS)
        assert masks is not None
        draws.append(torch.cat([m.reshape(2, -1) for m in masks.values()], dim=1).clone())
    values = torch.stack(draws)  # (draws, members, units): units in buffer order, ~50k per member and draw
    dropped = (values == 0).float()
    assert float(dropped.mean()) == pytest.approx(0.2, abs=0.005)
    # the sparse draw covers the whole buffer: its last units are dropped as often as its first
    tenth = values.shape[-1] // 10
    assert float(dropped[..., :tenth].mean()) == pytest.approx(0.2, abs=0.01)
    assert float(dropped[..., -tenth:].mean()) == pytest.approx(0.2, abs=0.01)
    assert torch.allclose(values[values != 0], torch.tensor(1 / 0.8))
    assert not torch.equal(values[:, 0], values[:, 1])  # each member has its own stream


def test_members_are_independent_and_state_round_trips() -> None:
    dims = {"a": 9, "b": 6}
    together = StackedAutoencoders(dims, default_groups(["a", "b"], True), [3, 4], ModelShape(dropout=0.1))
    alone = StackedAutoencoders(dims, default_groups(["a", "b"], True), [4], ModelShape(dropout=0.1))
    assert torch.equal(together.member(1).theta, alone.theta)  # seed 4 starts the same wherever it sits
    data = torch.randn(256, 15, generator=torch.Generator().manual_seed(0))
    opt_t, opt_a = together.make_optimizer(1e-3), alone.make_optimizer(1e-3)
    for start in range(0, 256, 64):
        together.train_step(data[start : start + 64].unsqueeze(0).expand(2, -1, -1).contiguous(), opt_t)
        alone.train_step(data[start : start + 64].unsqueeze(0), opt_a)
    torch.testing.assert_close(together.member(1).theta, alone.theta, rtol=1e-5, atol=1e-6)

    restored = StackedAutoencoders.from_state(together.state())
    assert torch.equal(restored.theta, together.theta)
    next_masks, restored_masks = together.draw_masks(64), restored.draw_masks(64)
    assert next_masks is not None and restored_masks is not None
    assert all(torch.equal(next_masks[k], restored_masks[k]) for k in next_masks)  # dropout streams continue


def test_the_model_is_an_nn_module_with_a_standard_state_dict() -> None:
    engine = StackedAutoencoders(TWO_SENSORS, default_groups(list(TWO_SENSORS), True), [0, 1], ModelShape())
    assert isinstance(engine, nn.Module)
    keys = list(engine.state_dict())
    assert "layers.unitac/enc_uskin/0.weight" in keys and "layers.ae_papillarray/dec/2.bias" in keys
    assert sum(p.numel() for p in engine.parameters()) == engine.theta.numel()
    copy = StackedAutoencoders(TWO_SENSORS, default_groups(list(TWO_SENSORS), True), [5, 6], ModelShape())
    copy.load_state_dict(engine.state_dict())  # the weights and each member's dropout stream
    assert torch.equal(copy.theta, engine.theta)
    a, b = engine.draw_masks(ROWS), copy.draw_masks(ROWS)
    assert a is not None and b is not None and all(torch.equal(a[k], b[k]) for k in a)


def test_state_loads_without_pickled_objects(tmp_path) -> None:  # type: ignore[no-untyped-def]
    engine = StackedAutoencoders(TWO_SENSORS, default_groups(list(TWO_SENSORS), True), [0, 1], ModelShape())
    torch.save(engine.state(), tmp_path / "state.pt")
    state = torch.load(tmp_path / "state.pt", weights_only=True)
    assert torch.equal(StackedAutoencoders.from_state(state).theta, engine.theta)


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


def test_a_sensor_name_with_a_dot_is_refused_as_it_would_break_the_state_dict_keys() -> None:
    with pytest.raises(ModelError, match=r"cannot contain a dot: pad\.v2"):
        StackedAutoencoders({"uskin": 72, "pad.v2": 12}, default_groups(["uskin", "pad.v2"], False), [0], ModelShape())

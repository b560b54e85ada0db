"""The engine's masked loss (contacts missing for some sensors) and frozen layers (a sensor added to a trained model):
each pair's MAE over the rows that have both sensors, nothing learned from a missing frame, and a frozen layer that
no training step can move."""

from __future__ import annotations

import torch

from unitac_rig.learning.engine import UNITAC_GROUP, ModelShape, StackedAutoencoders, default_groups

DIMS = {"a": 12, "b": 6, "c": 9}
ROWS = 16


def _batch(members: int, generator: torch.Generator) -> torch.Tensor:
    return torch.randn(members, ROWS, sum(DIMS.values()), generator=generator)


def _expected_loss(engine: StackedAutoencoders, batch: torch.Tensor, present: torch.Tensor) -> torch.Tensor:
    """Sum over (source, target) of mean |decode(encode(source))[target] - target| over rows with both, per member,
    through the engine's inference path (no dropout)."""
    columns, start = {}, 0
    for s, d in DIMS.items():
        columns[s] = slice(start, start + d)
        start += d
    total = torch.zeros(engine.members)
    for i, source in enumerate(DIMS):
        decoded = engine.decode(UNITAC_GROUP, engine.encode(UNITAC_GROUP, source, batch[..., columns[source]]))
        for j, target in enumerate(DIMS):
            both = present[..., i] * present[..., j]  # (members, rows)
            error = (decoded[target] - batch[..., columns[target]]).abs().mean(dim=-1)  # (members, rows)
            total += (error * both).sum(dim=1) / both.sum(dim=1)
    return total


def test_masked_loss_is_each_pairs_mae_over_rows_with_both_and_ignores_missing_frames() -> None:
    generator = torch.Generator().manual_seed(0)
    shape = ModelShape(dropout=0.0)
    engine = StackedAutoencoders(DIMS, default_groups(list(DIMS), False), [1, 2], shape)
    batch = _batch(2, generator)
    present = (torch.rand(2, ROWS, 3, generator=generator) > 0.3).float()
    present[:, :2] = 1.0  # every pair has rows
    expected = _expected_loss(engine, batch, present)

    # the frames of missing sensors hold filler; whatever it is must not matter
    column_present = torch.cat([present[..., i : i + 1].expand(-1, -1, d) for i, d in enumerate(DIMS.values())], -1)
    filled_zero = torch.where(column_present.bool(), batch, torch.zeros(()))
    filled_junk = torch.where(column_present.bool(), batch, torch.full((), 1e3))
    results = []
    for filled in (filled_zero, filled_junk):
        copy = StackedAutoencoders.from_state(engine.state())
        optimizer = torch.optim.SGD(copy.trainable_parameters(), lr=0.0)
        loss = copy.train_step(filled, optimizer, present=present)
        results.append((loss[0], [p.grad.clone() for p in copy.parameters()]))  # type: ignore[union-attr]
    torch.testing.assert_close(results[0][0], expected, rtol=1e-5, atol=1e-6)
    assert torch.equal(results[0][0], results[1][0])
    assert all(torch.equal(g0, g1) for g0, g1 in zip(results[0][1], results[1][1], strict=True))

    # all present: the same number as the unmasked loss
    full = torch.ones(2, ROWS, 3)
    a = StackedAutoencoders.from_state(engine.state())
    b = StackedAutoencoders.from_state(engine.state())
    masked = a.train_step(batch, torch.optim.SGD(a.trainable_parameters(), lr=0.0), present=full)
    plain = b.train_step(batch, torch.optim.SGD(b.trainable_parameters(), lr=0.0))
    torch.testing.assert_close(masked, plain, rtol=1e-6, atol=1e-7)


def test_a_new_sensor_trains_only_its_encoder_and_head_and_keeps_old_outputs_bit_identical() -> None:
    generator = torch.Generator().manual_seed(1)
    old_dims = {"a": 12, "b": 6}
    trained = StackedAutoencoders(old_dims, default_groups(list(old_dims), True), [1, 2], ModelShape())
    grown = trained.with_new_sensor("c", 9)
    assert grown.sensors == ("a", "b", "c")
    assert grown.group(UNITAC_GROUP).output_heads == (("a", "b"), ("c",))
    new_layers = {k for k in grown.weights if k not in trained.weights}
    assert new_layers == {"unitac/enc_c/0", "unitac/enc_c/1", "unitac/enc_c/2", "unitac/head_c/2"}
    assert grown.frozen == frozenset(trained.weights)

    x = torch.randn(5, 12, generator=generator)
    before = trained.decode(UNITAC_GROUP, trained.encode(UNITAC_GROUP, "a", x))
    optimizer = grown.make_optimizer(1e-2)
    assert sum(p.numel() for g in optimizer.param_groups for p in g["params"]) == sum(
        grown.weights[k].numel() + grown.biases[k].numel() for k in new_layers
    )
    start = {k: (grown.weights[k].clone(), grown.biases[k].clone()) for k in grown.weights}
    present = torch.ones(2, ROWS, 3)
    present[:, ::2, 1] = 0.0  # half the contacts lack sensor b
    for _ in range(5):
        losses = grown.train_step(_batch(2, generator), optimizer, present=present)
    assert float(losses[1:].abs().sum()) == 0.0  # the baselines are wholly frozen: not run
    for key, (w, b) in start.items():
        moved = not torch.equal(grown.weights[key], w) or not torch.equal(grown.biases[key], b)
        assert moved == (key in new_layers), key

    after = grown.decode(UNITAC_GROUP, grown.encode(UNITAC_GROUP, "a", x))
    assert torch.equal(after["a"], before["a"]) and torch.equal(after["b"], before["b"])
    assert after["c"].shape == (2, 5, 9)

    restored = StackedAutoencoders.from_state(grown.state())
    assert restored.frozen == grown.frozen and restored.group(UNITAC_GROUP).heads == (("a", "b"), ("c",))
    assert torch.equal(restored.theta, grown.theta)
    single = grown.member(1, groups=[UNITAC_GROUP])
    assert single.frozen == {k for k in grown.frozen if k.startswith("unitac/")}
    alone = single.decode(UNITAC_GROUP, single.encode(UNITAC_GROUP, "a", x))["a"]
    torch.testing.assert_close(alone, after["a"][1:2])  # one member alone: the same up to the batched kernel's rounding


def test_the_alignment_term_ignores_missing_frames_too() -> None:
    generator = torch.Generator().manual_seed(3)
    engine = StackedAutoencoders(
        DIMS, default_groups(list(DIMS), False), [1], ModelShape(dropout=0.0, align_weight=1.0)
    )
    batch = _batch(1, generator)
    present = torch.ones(1, ROWS, 3)
    present[:, ::3, 2] = 0.0
    column_present = torch.cat([present[..., i : i + 1].expand(-1, -1, d) for i, d in enumerate(DIMS.values())], -1)
    losses = []
    for filler in (0.0, 1e3):
        copy = StackedAutoencoders.from_state(engine.state())
        filled = torch.where(column_present.bool(), batch, torch.full((), filler))
        losses.append(copy.train_step(filled, torch.optim.SGD(copy.trainable_parameters(), lr=0.0), present=present))
    assert torch.equal(losses[0], losses[1])

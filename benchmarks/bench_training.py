"""Training speed of the UniTac-NV trainer against the ways it could have been written with plain PyTorch, measured
in one run.

Three trainers train the same models from the same initial weights at the paper's batch size (64):

* ``autograd`` - the project's trainer (:class:`unitac_rig.learning.engine.StackedAutoencoders`): every model and
  seed stacked, one parameter tensor per layer, ``baddbmm``, ``loss.backward()``, fused Adam, sparse dropout masks
  drawn on the device, the training rows gathered once per epoch on the device;
* ``vmap`` - ``torch.func``: each member's plain network (:class:`unitac_rig.learning.network.Autoencoder`, sliced
  out of the stacked model) stacked over seeds with ``stack_module_state`` and run through ``vmap(functional_call)``
  (dropout ``randomness="different"``), fed by the same per-epoch gather, ``loss.backward()``, fused Adam;
* ``plain`` - the textbook loop: one plain network per model and seed, a shuffling ``DataLoader`` over a
  ``TensorDataset``, ``torch.optim.Adam`` with its defaults, models trained one after another.

A stack of n models is UniTac-NV alone (1), UniTac-NV and the two per-sensor baselines of one seed (3, the paper's
single run) or of five seeds (15, the 5-seed run). One stack step moves every model of the stack by one batch
(the plain loop does n single-model steps). Every cell runs for a fixed CPU time in each of several rounds, the
rounds interleaved so a burst of load on a shared machine hits every trainer alike; the median round counts. Rates
are per CPU-second of this process (its compute time at one thread), because on a shared machine wall time measures
the other jobs too; wall-clock rates are kept in the JSON.

Everything runs on the CPU at one torch thread, as ``unitac-rig train`` does on a CPU.

Why one module: three trainers (stacked, vmap, plain loop) run under one interleaved timing harness so
their numbers are comparable.

    nice -n 10 python benchmarks/bench_training.py [--data DIR] [--quick] [--out docs/figures]
        [--rounds 8] [--seconds-per-cell 0.6] [--paper-run-epochs 5] [--budget-epochs 100]

Also the 5-seed paper run's wall time and budget against accuracy. Data: ``--data DIR`` (session files), else
synthetic contacts of the paper's size (7 objects x 91 angles x 25 targets, irregular prism x 4 rotations = 22,750
pairs, 12,300 training pairs; unitac_rig.learning.synthetic_data). Writes OUT/bench_training.json and
OUT/bench_training.png. About 3 minutes on an idle 2-core box (more under load); ``--quick`` seconds.
"""

from __future__ import annotations

import argparse
import copy
import itertools
import statistics
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn
from torch.func import functional_call, stack_module_state, vmap
from torch.utils.data import DataLoader, TensorDataset

from drivers.layouts import PAPILLARRAY, USKIN
from unitac_rig.bench import default_out_dir, write_json
from unitac_rig.learning.data import PairedDataset, build_paired_dataset, load_sets
from unitac_rig.learning.engine import Autoencoder, ModelShape, StackedAutoencoders, default_groups
from unitac_rig.learning.run import computing_on
from unitac_rig.learning.synthetic_data import synthetic_matched_sets

TRAINERS = ("autograd", "vmap", "plain")
BATCH = 64
LEARNING_RATE = 5e-4
PAPER_EPOCHS = 1000
PAPER_SEEDS = 5

Step = Callable[[], torch.Tensor]  # one stack step; returns the summed loss of every model of the stack


@dataclass(frozen=True)
class TrainingBenchPlan:
    stack_sizes: tuple[int, ...] = (1, 3, 15)
    rounds: int = 8
    seconds_per_cell: float = 0.6  # CPU time each (trainer, stack) cell runs for in each round
    warmup_steps: int = 5
    paper_run_epochs: int = 5  # epochs of the real 5-seed `train()` run that the 1000-epoch figure extrapolates
    budget_epochs: int = 100  # budget vs accuracy run (UniTac-NV + baselines, one seed); 0 skips it
    eval_every: int = 5


def full_plan() -> TrainingBenchPlan:
    return TrainingBenchPlan()


def quick_plan() -> TrainingBenchPlan:
    return TrainingBenchPlan(
        stack_sizes=(1, 3),
        rounds=1,
        seconds_per_cell=0.05,
        warmup_steps=1,
        paper_run_epochs=4,
        budget_epochs=2,
        eval_every=1,
    )


def stack(size: int) -> tuple[list[int], bool]:
    """Seeds and whether the baselines are in, for a stack of ``size`` models."""
    if size == 1:
        return [0], False
    if size % 3 == 0:
        return list(range(size // 3)), True
    raise ValueError(f"a stack holds 1 model or a multiple of 3 (UniTac-NV + 2 baselines per seed), not {size}")


class _Batches:
    """Each member's rows in its own order, gathered on the device once per epoch; batches are slices of it (what
    :func:`unitac_rig.learning.train.train_epoch` does)."""

    def __init__(self, x: torch.Tensor, seeds: Sequence[int]) -> None:
        self.x = x
        self.rngs = [np.random.default_rng([seed, 1]) for seed in seeds]
        self.start = x.shape[0]
        self.shuffled = x[None]

    def next(self) -> torch.Tensor:
        n = self.x.shape[0]
        if self.start >= n:
            order = torch.from_numpy(np.stack([rng.permutation(n) for rng in self.rngs])).to(self.x.device)
            self.shuffled = self.x[order]
            self.start = 0
        chunk = self.shuffled[:, self.start : self.start + BATCH]
        self.start += BATCH
        return chunk


def autograd_step(x: torch.Tensor, dims: dict[str, int], seeds: list[int], baselines: bool, shape: ModelShape) -> Step:
    engine = StackedAutoencoders(dims, default_groups(list(dims), baselines), seeds, shape)
    optimizer = engine.make_optimizer(LEARNING_RATE)
    batches = _Batches(x, seeds)
    return lambda: engine.train_step(batches.next(), optimizer).sum()


def _modules(dims: dict[str, int], seeds: list[int], baselines: bool, shape: ModelShape) -> list[list[Autoencoder]]:
    """Per model of the stack (UniTac-NV, then each baseline), each seed's plain network, sliced out of the stacked
    model (so initialised as the stacked trainer initialises that seed)."""
    groups = default_groups(list(dims), baselines)
    init = StackedAutoencoders(dims, groups, seeds, shape)
    return [[init.network(group.name, member) for member in range(len(seeds))] for group in groups]


class _Loss(nn.Module):
    """``model.loss`` as ``forward``, so ``functional_call`` can run it."""

    def __init__(self, model: Autoencoder) -> None:
        super().__init__()
        self.model = model

    def forward(self, *inputs: torch.Tensor) -> torch.Tensor:
        return self.model.loss(list(inputs))


def vmap_step(x: torch.Tensor, dims: dict[str, int], seeds: list[int], baselines: bool, shape: ModelShape) -> Step:
    columns = dict(zip(dims, torch.split(torch.arange(x.shape[1]), list(dims.values())), strict=True))
    models = []
    for per_seed in _modules(dims, seeds, baselines, shape):
        params, buffers = stack_module_state([_Loss(m) for m in per_seed])  # leaves with requires_grad
        base = copy.deepcopy(_Loss(per_seed[0])).to("meta")
        sensors = per_seed[0].sensors

        def member_loss(p: dict, b: dict, *inputs: torch.Tensor, base: nn.Module = base) -> torch.Tensor:
            return functional_call(base, (p, b), inputs)

        batched = vmap(member_loss, in_dims=(0, 0, *([0] * len(sensors))), randomness="different")
        models.append((params, buffers, sensors, batched))
    optimizer = torch.optim.Adam([p for params, *_ in models for p in params.values()], lr=LEARNING_RATE, fused=True)
    batches = _Batches(x, seeds)

    def step() -> torch.Tensor:
        batch = batches.next()
        optimizer.zero_grad(set_to_none=True)
        loss = sum(
            fn(params, buffers, *(batch[..., columns[s]] for s in sensors)).sum()
            for params, buffers, sensors, fn in models
        )
        assert isinstance(loss, torch.Tensor)
        loss.backward()
        optimizer.step()
        return loss.detach()

    return step


def plain_step(x: torch.Tensor, dims: dict[str, int], seeds: list[int], baselines: bool, shape: ModelShape) -> Step:
    per_model = []
    split = dict(zip(dims, torch.split(x, list(dims.values()), dim=1), strict=True))
    for per_seed in _modules(dims, seeds, baselines, shape):
        for seed, module in zip(seeds, per_seed, strict=True):
            loader = DataLoader(
                TensorDataset(*(split[s] for s in module.sensors)),
                batch_size=BATCH,
                shuffle=True,
                generator=torch.Generator().manual_seed(seed),
            )
            per_model.append(_PlainModel(module, loader))

    def step() -> torch.Tensor:
        return torch.stack([model.step() for model in per_model]).sum()

    return step


class _PlainModel:
    """One model of the textbook loop, a step at a time: the next batch of a shuffling ``DataLoader`` over a
    ``TensorDataset``, the module's loss, ``zero_grad``, ``backward``, ``torch.optim.Adam`` with its defaults."""

    def __init__(self, module: Autoencoder, loader: DataLoader) -> None:
        self.module = module.train()
        self.loader = loader
        self.batches = iter(loader)
        self.optimizer = torch.optim.Adam(module.parameters(), lr=LEARNING_RATE)

    def step(self) -> torch.Tensor:
        try:
            batch = next(self.batches)
        except StopIteration:
            self.batches = iter(self.loader)
            batch = next(self.batches)
        loss = self.module.loss(batch)
        self.optimizer.zero_grad()
        loss.backward()
        self.optimizer.step()
        return loss.detach()


BUILDERS: dict[str, Callable[..., Step]] = {
    "autograd": autograd_step,
    "vmap": vmap_step,
    "plain": plain_step,
}


def build_step(trainer: str, x: torch.Tensor, dims: dict[str, int], size: int, shape: ModelShape) -> Step:
    seeds, baselines = stack(size)
    return BUILDERS[trainer](x, dims, seeds, baselines, shape)


def training_matrix(dataset: PairedDataset) -> tuple[torch.Tensor, dict[str, int], int]:
    """Normalised training rows (sensor columns side by side), feature dims, and the number of pairs, split and
    normalised as ``train()`` does."""
    from unitac_rig.learning.data import Normaliser, split_by_direction

    split = split_by_direction(dataset, 0)
    normaliser = Normaliser.fit(dataset, split.train_mask)
    rows = dataset.subset(split.train_mask)
    x = np.concatenate([normaliser.normalise(s, rows.values[s]) for s in dataset.sensors], axis=1)
    return torch.from_numpy(x), {s: dataset.n_taxels(s) * 3 for s in dataset.sensors}, len(rows)


def measure_rates(x: torch.Tensor, dims: dict[str, int], plan: TrainingBenchPlan) -> dict[str, dict[str, Any]]:
    """Stack steps per CPU-second of every trainer at every stack size: rounds interleaved, each cell run for
    ``plan.seconds_per_cell`` of this process's CPU time. CPU time, not wall time, because on a machine shared with
    other jobs the wall time says more about them than about the trainer (one thread: CPU time = compute time).
    Returns {trainer: {size: {"steps_per_s": median round, "rounds": [...], "wall_steps_per_s": [...]}}}."""
    steps = {(t, n): build_step(t, x, dims, n, ModelShape()) for t in TRAINERS for n in plan.stack_sizes}
    for step in steps.values():
        for _ in range(plan.warmup_steps):
            step()
    rounds: dict[tuple[str, int], list[float]] = {key: [] for key in steps}
    wall: dict[tuple[str, int], list[float]] = {key: [] for key in steps}
    for _ in range(plan.rounds):
        for key, step in steps.items():
            done, cpu_began, wall_began = 0, time.process_time(), time.perf_counter()
            while True:
                step()
                done += 1
                cpu = time.process_time() - cpu_began
                if cpu >= plan.seconds_per_cell:
                    break
            rounds[key].append(done / cpu)
            wall[key].append(done / (time.perf_counter() - wall_began))
    return {
        trainer: {
            str(n): {
                "steps_per_s": statistics.median(rounds[trainer, n]),
                "rounds": rounds[trainer, n],
                "wall_steps_per_s": wall[trainer, n],
            }
            for n in plan.stack_sizes
        }
        for trainer in TRAINERS
    }


def measure_paper_run(dataset: PairedDataset, epochs: int) -> dict[str, Any]:
    """The real 5-seed run (``train()`` with UniTac-NV + baselines) for ``epochs`` (at least 4), in CPU seconds (see
    :func:`measure_rates`), extrapolated to the paper's 1000 epochs.

    The paper's split (no validation rows, all 12,300 training pairs): ``train()`` then scores the test set after the
    first and the last epoch only, so the epochs between are training alone and the last one's extra is one
    evaluation of the five seeds."""
    from unitac_rig.learning.train import TrainConfig, train

    if epochs < 4:
        raise ValueError("the paper run needs at least 4 epochs: two of training alone, then one with evaluation")
    cpu: list[float] = []
    wall: list[float] = []

    def stamp(_: dict[str, Any]) -> None:  # called after each epoch's training and evaluation
        cpu.append(time.process_time())
        wall.append(time.perf_counter())

    config = TrainConfig(epochs=epochs, seeds=tuple(range(PAPER_SEEDS)), eval_every=epochs, val_fraction=0.0)
    with tempfile.TemporaryDirectory() as tmp:
        began = time.process_time()
        train(dataset, Path(tmp) / "run", config, device="cpu", progress=stamp)
        checkpoint = time.process_time() - cpu[-1]  # the last epoch's checkpoint is saved after its progress call
    epochs_cpu = [b - a for a, b in itertools.pairwise(cpu)]  # epochs 2..E
    train_epoch = statistics.median(epochs_cpu[:-1])  # epochs 2..E-1: no evaluation
    evaluation = max(0.0, epochs_cpu[-1] - train_epoch)
    setup = max(0.0, cpu[0] - began - train_epoch - evaluation)  # split, normalisation, test set, t-SNE latents
    checkpoints = PAPER_EPOCHS // config.checkpoint_every
    return {
        "epochs_measured": epochs,
        "clock": "process CPU seconds",
        "train_seconds_per_epoch": train_epoch,
        "train_seconds_epochs": epochs_cpu[:-1],
        "eval_seconds_per_evaluation": evaluation,
        "checkpoint_seconds": checkpoint,
        "setup_seconds": setup,
        "wall_over_cpu": (wall[-1] - wall[0]) / max(cpu[-1] - cpu[0], 1e-9),  # > 1: other jobs took the CPU
        "extrapolated_1000_epochs": {
            "train_only_s": PAPER_EPOCHS * train_epoch,
            "end_to_end_s": setup + PAPER_EPOCHS * train_epoch + 2 * evaluation + checkpoints * checkpoint,
        },
    }


def measure_budget(dataset: PairedDataset, epochs: int, eval_every: int) -> dict[str, Any]:
    """Validation NMAE / SSIM (held-out directions of the training objects, one seed) against epochs for UniTac-NV +
    baselines, with ``train()``'s default validation split; the test rows are scored after epoch 1 and the end."""
    from unitac_rig.learning.train import TrainConfig, train

    config = TrainConfig(epochs=epochs, eval_every=eval_every, checkpoint_every=10**6, tsne_contacts=10)
    with tempfile.TemporaryDirectory() as tmp:
        began = time.process_time()
        outcome = train(dataset, Path(tmp) / "run", config, device="cpu")
        cpu_seconds = time.process_time() - began
    curve = []
    for record in outcome.history:
        scored = record.get("val") or record.get("test")  # validation curves; test only at epoch 1 and the end
        if scored is None:
            continue
        entry: dict[str, Any] = {"epoch": record["epoch"], "seconds": record["seconds"]}
        seen = scored.get("seen", {})
        for column, metrics in seen.items():
            if not isinstance(metrics, dict):  # latent alignment entries: one value per member
                entry[f"seen/{column}"] = metrics[0]
            else:
                entry[f"seen/{column}/nmae"] = metrics["nmae"][0]
                entry[f"seen/{column}/ssim"] = metrics["ssim"][0]
        curve.append(entry)
    return {
        "epochs": epochs,
        "eval_every": eval_every,
        "train_seconds": outcome.train_seconds,  # wall, training only
        "cpu_seconds": cpu_seconds,  # the whole call: training, evaluations, setup
        "curve": curve,
    }


def run_training_benchmark(dataset: PairedDataset, source: str, plan: TrainingBenchPlan) -> dict[str, Any]:
    """Every measurement of this module on ``dataset``, at one torch thread; a JSON-ready dict."""
    from unitac_rig.bench import machine_info

    load_before = machine_info()["load_average_1min"]
    with computing_on("cpu", 1):
        x, dims, n_train = training_matrix(dataset)
        began = time.perf_counter()
        rates = measure_rates(x, dims, plan)
        rates_seconds = time.perf_counter() - began
        paper = measure_paper_run(dataset, plan.paper_run_epochs)
        budget = measure_budget(dataset, plan.budget_epochs, plan.eval_every) if plan.budget_epochs else None
    steps_per_epoch = -(-n_train // BATCH)
    largest = str(max(plan.stack_sizes))
    return {
        "benchmark": "training",
        "data": source,
        "pairs": len(dataset),
        "train_rows": n_train,
        "batch_size": BATCH,
        "torch": torch.__version__,
        "torch_threads": 1,
        "machine": machine_info(),
        "load_average_1min_at_start": load_before,
        "plan": asdict(plan),
        "rates": rates,
        "rates_wall_seconds": rates_seconds,
        "ratios": ratios(rates),
        "paper_run": paper,
        "paper_run_train_only_from_rates_s": {
            trainer: PAPER_EPOCHS * steps_per_epoch / rates[trainer][largest]["steps_per_s"] for trainer in TRAINERS
        },
        "paper_run_stack": largest,
        "budget_run": budget,
    }


def ratios(rates: dict[str, dict[str, Any]]) -> dict[str, dict[str, float]]:
    """Per stack size: how many times faster the autograd trainer is than each other trainer (< 1: slower)."""
    return {
        other: {n: rates["autograd"][n]["steps_per_s"] / cell["steps_per_s"] for n, cell in rates[other].items()}
        for other in TRAINERS
        if other != "autograd"
    }


def summary_lines(doc: dict[str, Any]) -> list[str]:
    lines = [f"data: {doc['data']}: {doc['pairs']} pairs, {doc['train_rows']} training rows, batch {doc['batch_size']}"]
    sizes = list(doc["rates"]["autograd"])
    lines.append("stack steps/CPU-s (median round)  " + " ".join(f"{n:>9} models" for n in sizes))
    for trainer in TRAINERS:
        cells = " ".join(f"{doc['rates'][trainer][n]['steps_per_s']:16.1f}" for n in sizes)
        lines.append(f"  {trainer:<31}{cells}")
    for other, by_size in doc["ratios"].items():
        lines.append(f"  autograd / {other:<20}" + " ".join(f"{by_size[n]:15.2f}x" for n in sizes))
    paper = doc["paper_run"]
    extra = paper["extrapolated_1000_epochs"]
    lines.append(
        f"5-seed paper run (train(), {paper['epochs_measured']} epochs measured, 1000 extrapolated, CPU time; wall was "
        f"{paper['wall_over_cpu']:.1f}x CPU): training {paper['train_seconds_per_epoch']:.2f} s/epoch, evaluation "
        f"{paper['eval_seconds_per_evaluation']:.2f} s; 1000 epochs: train only {extra['train_only_s'] / 60:.1f} min, "
        f"end to end {extra['end_to_end_s'] / 60:.1f} min"
    )
    lines.append(
        f"1000 epochs of the {doc['paper_run_stack']}-model stack from the rates (training only): "
        + ", ".join(f"{t} {s / 60:.1f} min" for t, s in doc["paper_run_train_only_from_rates_s"].items())
    )
    if doc["budget_run"]:
        budget = doc["budget_run"]
        lines.append(
            f"budget run: {budget['epochs']} epochs (UniTac-NV + 2 baselines): training "
            f"{budget['train_seconds']:.1f} s wall; {budget['cpu_seconds']:.1f} CPU-s with evaluation every "
            f"{budget['eval_every']}"
        )
    return lines


def plot_training_benchmark(doc: dict[str, Any], path: Path) -> Path:
    """Stack steps/s per trainer and stack size; the 5-seed paper run's 1000 epochs; budget against accuracy."""
    from unitac_rig.plotting import new_figure, save_figure

    fig = new_figure(14.0, 9.0)
    (ax_rate, ax_paper), (ax_nmae, ax_ssim) = fig.subplots(2, 2)
    sizes = list(doc["rates"]["autograd"])
    colours = {"autograd": "tab:green", "vmap": "tab:orange", "plain": "0.55"}
    width = 0.8 / len(TRAINERS)
    for i, trainer in enumerate(TRAINERS):
        cells = [doc["rates"][trainer][n] for n in sizes]
        median = np.array([c["steps_per_s"] for c in cells])
        low = median - np.array([min(c["rounds"]) for c in cells])
        high = np.array([max(c["rounds"]) for c in cells]) - median
        xs = np.arange(len(sizes)) + (i - (len(TRAINERS) - 1) / 2) * width
        ax_rate.bar(xs, median, width, yerr=[low, high], capsize=2, color=colours[trainer], label=trainer)
        for xpos, value in zip(xs, median, strict=True):
            ax_rate.text(xpos, value / 1.15, f"{value:.0f}", ha="center", va="top", fontsize=7, color="white")
    ax_rate.set_xticks(np.arange(len(sizes)), [f"{n} model{'s' if n != '1' else ''}" for n in sizes])
    ax_rate.set_yscale("log")
    top = max(cell["steps_per_s"] for cells in doc["rates"].values() for cell in cells.values())
    ax_rate.set_ylim(top=top * 2.0)
    ax_rate.set_ylabel("stack steps per CPU-second")
    ax_rate.set_title(
        "every model of the stack one batch (64) further; 1 thread; bars: median round, whiskers: range", fontsize=9
    )
    ax_rate.legend(fontsize=8)
    ax_rate.grid(axis="y", which="both", alpha=0.3)

    from_rates = doc["paper_run_train_only_from_rates_s"]
    extra = doc["paper_run"]["extrapolated_1000_epochs"]
    labels = [f"{t}\ntraining only" for t in TRAINERS] + ["autograd, train()\nend to end"]
    minutes = [from_rates[t] / 60 for t in TRAINERS] + [extra["end_to_end_s"] / 60]
    bars = ax_paper.bar(labels, minutes, color=[colours[t] for t in TRAINERS] + ["darkgreen"])
    for bar, value in zip(bars, minutes, strict=True):
        ax_paper.text(bar.get_x() + bar.get_width() / 2, value, f"{value:.1f}", ha="center", va="bottom", fontsize=8)
    ax_paper.set_ylabel("CPU minutes for 1000 epochs (extrapolated)")
    ax_paper.set_title(
        f"1000 epochs, {doc['train_rows']} training pairs: {doc['paper_run_stack']}-model stack from the rates,\n"
        "and the 5-seed run through train() (training + evaluation + checkpoints)",
        fontsize=9,
    )
    ax_paper.tick_params(axis="x", labelsize=7)
    ax_paper.grid(axis="y", alpha=0.3)

    budget = doc.get("budget_run")
    if budget and budget["curve"]:
        curve = budget["curve"]
        epochs = [c["epoch"] for c in curve]
        columns = sorted({k.split("/")[1] for k in curve[0] if k.endswith("/nmae")})
        for column in columns:
            style = "--" if column.startswith("ae_") else "-"
            label = column.replace("_to_", " → ")
            ax_nmae.plot(epochs, [c[f"seen/{column}/nmae"] for c in curve], style, label=label)
            ax_ssim.plot(epochs, [c[f"seen/{column}/ssim"] for c in curve], style, label=label)
        for ax, name in ((ax_nmae, "validation NMAE"), (ax_ssim, "validation SSIM")):
            ax.set_xlabel(f"epoch (UniTac-NV + 2 baselines, one seed; {budget['cpu_seconds']:.0f} CPU-s in all)")
            ax.set_ylabel(name)
            ax.grid(alpha=0.3)
        ax_nmae.set_yscale("log")
        ax_nmae.legend(fontsize=7)
    fig.suptitle(
        f"UniTac-NV training speed ({doc['data']}; {doc['machine']['cpus']} CPUs shared, load average "
        f"{doc['load_average_1min_at_start']} at start, {doc['machine']['load_average_1min']} at end)",
        fontsize=10,
    )
    return save_figure(fig, path)


PAPER_OBJECTS = ("circle_pla", "square_pla", "hex_pla", "circle_tpu", "square_tpu", "hex_tpu", "irregular_pla")
QUICK_OBJECTS = ("circle_pla", "hex_tpu", "irregular_pla")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, default=None, help="session files (default: paper-sized synthetic)")
    parser.add_argument("--quick", action="store_true", help="smoke run: small data, short timings")
    parser.add_argument("--out", type=Path, default=default_out_dir(), help="folder for the JSON and PNG")
    parser.add_argument("--rounds", type=int, default=None)
    parser.add_argument("--seconds-per-cell", type=float, default=None)
    parser.add_argument("--paper-run-epochs", type=int, default=None)
    parser.add_argument("--budget-epochs", type=int, default=None, help="0 skips the budget/accuracy run")
    args = parser.parse_args()

    plan = quick_plan() if args.quick else full_plan()
    overrides = {
        "rounds": args.rounds,
        "seconds_per_cell": args.seconds_per_cell,
        "paper_run_epochs": args.paper_run_epochs,
        "budget_epochs": args.budget_epochs,
    }
    plan = replace(plan, **{k: v for k, v in overrides.items() if v is not None})

    began = time.perf_counter()
    if args.data:
        sets, source = load_sets(args.data), str(args.data)
    elif args.quick:
        angles = tuple(float(a) for a in range(-45, 46, 9))
        sets = synthetic_matched_sets(
            QUICK_OBJECTS, [USKIN, PAPILLARRAY], angles_deg=angles, targets_n=(4.0, 7.0, 10.0)
        )
        source = "synthetic (unitac_rig.learning.synthetic_data), small"
    else:
        sets = synthetic_matched_sets(PAPER_OBJECTS, [USKIN, PAPILLARRAY])
        source = "synthetic (unitac_rig.learning.synthetic_data), paper-sized"
    dataset = build_paired_dataset(sets)
    print(f"data ready in {time.perf_counter() - began:.1f} s")

    doc = run_training_benchmark(dataset, source, plan)
    for line in summary_lines(doc):
        print(line)
    json_path = write_json(doc, args.out / "bench_training.json")
    png_path = plot_training_benchmark(doc, args.out / "bench_training.png")
    print(f"wrote {json_path} and {png_path} ({time.perf_counter() - began:.0f} s in all)")


if __name__ == "__main__":
    main()

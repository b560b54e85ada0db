"""The dataset cards (``README.md``) of the exports: the YAML front matter a dataset hub reads, what a colleague
needs to know, and how to load the data. :func:`pairs_card` is the Parquet export's (:mod:`.export`),
:func:`lerobot_card` and :func:`lerobot_sensor_card` the LeRobot export's (:mod:`.lerobot`, with loading code that
works beside torch's CPU build and the paper's citation); each renders the summary document its exporter writes into
``manifest.json``."""

from __future__ import annotations

import time
from typing import Any

from unitac_rig.storage.manifest import MANIFEST_NAME

PARQUET_NAME = "pairs.parquet"

LICENSE = "cc-by-4.0"  # proposed on the cards; the data's owner changes it before publishing if theirs differs
CITATION = """@inproceedings{hou2025unitacnv,
  title     = {{UniTac-NV}: A Unified Tactile Representation For Non-Vision-Based Tactile Sensors},
  author    = {Hou, Jian and Zhou, Xin and Yang, Qihan and Spiers, Adam J.},
  booktitle = {IEEE/RSJ International Conference on Intelligent Robots and Systems (IROS)},
  pages     = {17854--17860},
  year      = {2025},
  note      = {arXiv:2506.19699}
}"""
# LeRobot datasets need torchvision importable; PyPI's torchvision is a CUDA build, whose extension does not load next
# to torch's CPU build ("operator torchvision::nms does not exist"). The cards' loading code carries this guard (the
# datasets have no images: no torchvision op is ever called); with a matching torchvision it does nothing.
TORCHVISION_GUARD = """import sys

import torch

try:
    import torchvision  # noqa: F401
except RuntimeError:  # a CUDA torchvision next to a CPU torch: define the two ops its import registers
    for name in [m for m in sys.modules if m.split(".")[0] == "torchvision"]:
        del sys.modules[name]
    ops = torch.library.Library("torchvision", "DEF")
    ops.define("nms(Tensor dets, Tensor scores, float iou_threshold) -> Tensor")
    ops.define("qnms(Tensor dets, Tensor scores, float iou_threshold) -> Tensor")
from ledataset.datasets.lerobot_dataset import LeRobotDataset  # pip install lerobot-dataset
"""


def size_category(n: int) -> str:
    """The Hub's ``size_categories`` bucket of ``n`` rows (frames): by the number of digits."""
    names = ("n<1K", "1K<n<10K", "10K<n<100K", "100K<n<1M", "1M<n<10M", "10M<n<100M", "100M<n<1B")
    return names[min(len(names) - 1, max(0, len(str(max(n, 1))) - 3))]


def _load_and_cite(loading: list[str]) -> list[str]:
    """A card's guarded loading code (``loading``: the lines after the import) and the paper's citation."""
    return [
        "```python",
        TORCHVISION_GUARD.rstrip(),
        "",
        *loading,
        "```",
        "",
        "The `except` branch is for torch's CPU build beside PyPI's torchvision (a CUDA build, whose extension "
        "then fails with `operator torchvision::nms does not exist`); these datasets hold no images, so no "
        "torchvision op is called.",
        "",
        "## Citation",
        "",
        "```bibtex",
        CITATION,
        "```",
        "",
    ]


def lerobot_sensor_card(sensor: str, d: dict[str, Any], doc: dict[str, Any]) -> str:
    """``<sensor>/README.md``: the card of one sensor's dataset, the folder that is uploaded as a Hub dataset."""
    layout = d["layout"]
    simulated = ""
    if d["simulated"]:
        simulated = " Recorded on the **simulated rig**: contact mechanics and sensor responses are models."
    lines = [
        "---",
        f"license: {LICENSE}",
        "task_categories: [robotics]",
        f"size_categories: [{size_category(int(d['frames']))}]",
        f"tags: [LeRobot, tactile, unitac-rig, unitac-nv, {sensor}]",
        "configs:",
        "- config_name: default",
        "  data_files: data/*/*.parquet",
        "---",
        "",
        f"# Tactile presses, {layout['model']} ({sensor}): a LeRobotDataset v3.0",
        "",
        f"Presses of 3D-printed prisms onto a {layout['model']} pad ({layout['rows']} x {layout['cols']} taxels, "
        f"x/y/z in {layout['units']}) by a UR5e arm, recorded with unitac-rig.{simulated} One episode per press "
        f"({d['episodes']}), one row per tactile frame ({d['frames']}, {d['fps']} fps nominal), with the wrist "
        f"wrench and TCP pose sampled at that frame. Objects: {', '.join(d['objects'])}.",
        "",
        "Every feature's dtype, shape, names, `unit` and `description` are in `meta/info.json`; per-episode press "
        "metadata, force matching (`extraction/*`) and per-episode statistics (`stats/*`) are columns of "
        "`meta/episodes/`.",
        "",
        "## Load it",
        "",
        *_load_and_cite(
            [
                f'ds = LeRobotDataset("local/{sensor}", root=".")  # or this dataset\'s Hub repository id',
                f'frame = ds[0]["observation.tactile.{sensor}"]  # ({layout["n_taxels"]}, 3), tared',
            ]
        ),
        f"Exported by unitac-rig {doc['exported_by']['package_version']}; the export's `{MANIFEST_NAME}` lists "
        "every file with its SHA-256.",
        "",
    ]
    return "\n".join(lines)


def lerobot_card(doc: dict[str, Any]) -> str:
    """The LeRobot export's README.md: what the datasets are, how to load them with LeRobot, the features and limits."""
    datasets = doc["datasets"]
    simulated = all(d["simulated"] for d in datasets.values())
    lines = [
        "---",
        f"license: {LICENSE}",
        "tags: [tactile, robotics, LeRobot, unitac-rig]",
        "task_categories: [robotics]",
        f"size_categories: [{size_category(sum(int(d['frames']) for d in datasets.values()))}]",
        "configs:",
        *(line for s in datasets for line in (f"- config_name: {s}", f"  data_files: {s}/data/*/*.parquet")),
        "---",
        "",
        "# Tactile press dataset (unitac-rig export, LeRobotDataset v3.0)",
        "",
        "Presses of 3D-printed prisms onto a tactile pad by a UR5e arm"
        + (
            " (**simulated rig**: contact mechanics and sensor responses are models, not measurements)"
            if simulated
            else ""
        )
        + ". One LeRobot dataset per sensor (each at its own frame rate); one episode per press, one row per "
        "tactile frame, with the wrist wrench and TCP pose sampled at that frame.",
        "",
        "| dataset | sensor model | taxels | frame unit | fps | episodes | frames | objects |",
        "|---|---|---|---|---:|---:|---:|---|",
        *(
            f"| `{s}/` | {d['layout']['model']} | {d['layout']['rows']} x {d['layout']['cols']} | "
            f"{d['layout']['units']} | {d['fps']} | {d['episodes']} | {d['frames']} | {', '.join(d['objects'])} |"
            for s, d in datasets.items()
        ),
        "",
        "## Load it",
        "",
        "In this folder (each `<sensor>/` folder is a complete dataset with its own card; on the Hub, pass its "
        "repository id instead of `local/...` and drop `root`):",
        "",
        *_load_and_cite([f'{s} = LeRobotDataset("local/{s}", root="{s}")' for s in datasets]),
        "With the full lerobot package: `from lerobot.datasets.lerobot_dataset import LeRobotDataset`.",
        "",
        "Every feature's dtype, shape, names, `unit` and `description` are in `<sensor>/meta/info.json`; per-episode "
        "press metadata (object, rotation, angle, status, tare baseline, and the force-matching `extraction/*`) are "
        "columns of `<sensor>/meta/episodes/`. `annotation.matched_targets` marks the frames force-matched to each "
        "target force: those are the frames of unitac-rig's paired dataset (`unitac-rig train --data` reads this "
        "export back).",
        "",
        "## Limits",
        "",
        "- Tactile frames are tare-subtracted, in each sensor's own unit (uSkin raw counts are not newtons).",
        "- `timestamp` is the measured host time since the press's first frame; `fps` is the sensor's nominal rate. "
        "LeRobot turns `delta_timestamps` into row offsets with `fps`, so a delta lands on the row that far back, "
        "which is that far back in time within the sensor's jitter.",
        "- There is no `action`: the press is a scripted force-terminated move (see the episode's `unitac/*` columns).",
        "",
        f"Exported by unitac-rig {doc['exported_by']['package_version']}; `{MANIFEST_NAME}` lists every file with its "
        "SHA-256 (`unitac-rig verify .`).",
        "",
    ]
    return "\n".join(lines)


def pairs_card(doc: dict[str, Any]) -> str:
    """The Parquet export's card: what the pairs are, how to load them, columns, sensors, sessions, limits."""
    exported = doc["exported_by"]
    lines = [
        *_card_intro(doc),
        *_card_tables(doc),
        *_card_limits(doc),
        "",
        f"Exported by unitac-rig {exported['package_version']} (commit `{str(exported['git_commit'])[:12]}`) on "
        f"{time.strftime('%Y-%m-%d %H:%M', time.localtime(doc['created_unix']))}; `{MANIFEST_NAME}` lists every file "
        "with its SHA-256.",
        "",
    ]
    return "\n".join(lines)


def _card_intro(doc: dict[str, Any]) -> list[str]:
    """The card's front matter, what the dataset is, and how to load it."""
    counts = doc["counts"]
    sensors = list(doc["sensors"])
    kind = "the simulated rig (the project's twin)" if doc["simulated"] else "a UR5e press rig"
    return [
        "---",
        "pretty_name: unitac-rig paired tactile dataset",
        "tags: [tactile, robotics, cross-sensor, unitac-rig]",
        "configs:",
        "- config_name: default",
        "  data_files:",
        "  - split: train",
        f"    path: {PARQUET_NAME}",
        "---",
        "",
        "# Paired tactile dataset (unitac-rig export)",
        "",
        f"{counts['contacts']} contacts, each recorded by every one of {len(sensors)} sensors ({', '.join(sensors)}): "
        f"{counts['rows']} rows in `{PARQUET_NAME}`, from {counts['sessions']} sessions recorded on {kind}. "
        "Every contact is one press of an object at one rotation and approach angle, at one target force; each "
        "sensor's row holds its tactile frame at the moment the wrist force crossed that target.",
        "",
        "## Load it",
        "",
        "```python",
        "import pandas as pd",
        f'df = pd.read_parquet("{PARQUET_NAME}")',
        "import numpy as np",
        'frame = np.stack(df.loc[0, "frame"])            # (n_taxels, 3), in the unit of df.loc[0, "frame_unit"]',
        "",
        "import datasets",
        f'ds = datasets.load_dataset("parquet", data_files="{PARQUET_NAME}")["train"]',
        "```",
        "",
        "Check the copy first: `unitac-rig verify .` (every file's SHA-256 against `manifest.json`).",
        "",
    ]


def _card_tables(doc: dict[str, Any]) -> list[str]:
    """The card's tables: columns, sensors, contacts per object, sessions."""
    return [
        "## Columns",
        "",
        "| column | unit | meaning |",
        "|---|---|---|",
        *(f"| `{c['name']}` | {c['unit'] or ''} | {c['description']} |" for c in doc["schema"]),
        "",
        "Rows of one `contact` share object, rotation, angle and target: pivot on `contact` to get the pairs. "
        "Units are also in the Parquet schema (each field's `unit` metadata).",
        "",
        "## Sensors",
        "",
        "| sensor | model | taxel grid | frame unit |",
        "|---|---|---|---|",
        *(
            f"| {s} | {info.get('model', '?')} | {info.get('rows', '?')} x {info.get('cols', '?')} "
            f"| {info.get('units', '?')} |"
            for s, info in doc["sensors"].items()
        ),
        "",
        "## Contacts per object",
        "",
        "| object | contacts |",
        "|---|---:|",
        *(f"| {o} | {n} |" for o, n in doc["counts"]["contacts_per_object"].items()),
        "",
        "## Sessions (raw recordings, HDF5, under `raw/`)",
        "",
        "| file | presses complete/planned | simulated | SHA-256 |",
        "|---|---|---|---|",
        *(
            f"| `{s['file']}` | {s['presses']['complete']}/{s['presses']['planned']} | "
            f"{'yes' if s['simulated'] else 'no'} | `{s['sha256'][:16]}…` |"
            for s in doc["sessions"]
        ),
        "",
        "The session format (raw arm and tactile streams, tare, events, the extraction) is documented in "
        "unitac-rig's docs/dataset.md; full provenance of each session (rig, software version, commit, sensor "
        "identity, extraction settings) is in `manifest.json`.",
        "",
    ]


def _card_limits(doc: dict[str, Any]) -> list[str]:
    """How the pairs were made and what they cannot be used for."""
    lines = [
        "## How it was made, and limits",
        "",
        "- Frames are force-matched: the tactile frame nearest the moment the smoothed wrist force first crossed "
        "each target on the loading ramp, kept only when within the extraction tolerance (`error_n`).",
        "- A contact is kept only when every sensor has it (join on object, rotation, angle, target); matched frames "
        "without a partner are left out ("
        + ", ".join(f"{s}: {n}" for s, n in doc["counts"]["matched_frames_without_partner"].items())
        + ").",
        "- Frames are tare-subtracted, in each sensor's own unit (uSkin raw counts are not newtons).",
        "- No train/test split is given. Do not split rows at random: the forces of one press are near-identical "
        "frames. Split by approach direction (object, rotation, angle), as unitac-rig's `train` does.",
    ]
    if doc["simulated"]:
        lines.append(
            "- **Simulated.** Recorded on the project's simulated rig: contact mechanics and sensor responses are "
            "models, not measurements; do not report results on it as real-sensor results."
        )
    return lines

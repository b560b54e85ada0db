"""Load a unitac-rig LeRobot export with the standalone ``lerobot-dataset`` package, as a LeRobot user would.

Run by ``test_lerobot_export.py`` with the Python of a separate virtual environment that holds lerobot-dataset (and
NOT unitac-rig): ``python lerobot_load_check.py EXPORT_DIR OUT.npz``. For every sensor dataset it loads
``LeRobotDataset``, reads every frame through ``__getitem__`` and writes what LeRobot returned (frames, indices,
features, stats, tasks, episodes) into OUT.npz for the test to compare with what was written.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import torch


def _import_torchvision() -> None:
    """torchvision's PyPI wheel is the CUDA build; next to the CPU build of torch its C extension cannot load, and
    its Python modules (all that lerobot-dataset imports for data without images or video) then fail only on
    registering fake kernels for two ops the extension would have defined. Defining those two schemas lets it import;
    no torchvision op is used by these datasets. With a torchvision whose extension loads, nothing is changed."""
    try:
        import torchvision
    except RuntimeError as exc:
        if "torchvision::nms" not in str(exc):
            raise
        for name in [m for m in sys.modules if m == "torchvision" or m.startswith("torchvision.")]:
            del sys.modules[name]
        library = torch.library.Library("torchvision", "DEF")
        library.define("nms(Tensor dets, Tensor scores, float iou_threshold) -> Tensor")
        library.define("qnms(Tensor dets, Tensor scores, float iou_threshold) -> Tensor")
        _KEEP.append(library)
        import torchvision  # noqa: F401


_KEEP: list[object] = []
_import_torchvision()

from ledataset.datasets.lerobot_dataset import LeRobotDataset  # noqa: E402


def main(root: Path, out: Path) -> None:
    arrays: dict[str, np.ndarray] = {}
    summary: dict[str, object] = {}
    for info_path in sorted(root.glob("*/meta/info.json")):
        sensor = info_path.parents[1].name
        ds = LeRobotDataset(f"local/{sensor}", root=info_path.parents[1])
        key = f"observation.tactile.{sensor}"
        items = [ds[i] for i in range(len(ds))]
        for name in (key, "observation.wrench", "timestamp", "episode_index", "index", "frame_index",
                     "annotation.matched_targets"):  # fmt: skip
            arrays[f"{sensor}/{name}"] = torch.stack([item[name] for item in items]).numpy()
        episodes = ds.meta.episodes
        summary[sensor] = {
            "len": len(ds),
            "num_episodes": ds.num_episodes,
            "fps": ds.fps,
            "features": ds.meta.features,
            "stats": {k: {s: np.asarray(v).tolist() for s, v in st.items()} for k, st in ds.meta.stats.items()},
            "tasks": [items[i]["task"] for i in range(len(items))][:: max(1, len(items) // 10)],
            "objects": sorted({item["annotation.object"] for item in items}),
            "episode_press_ids": list(episodes["unitac/press_id"]),
            "episode_lengths": list(episodes["length"]),
        }
    arrays["summary"] = np.array(json.dumps(summary, default=list))
    np.savez(out, **arrays)


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]))

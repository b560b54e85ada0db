"""Cross-sensor translation with a trained run: encode with the source sensor's encoder, decode with the shared
decoder, keep the target sensor's part, undo the normalisation.

    from unitac_rig.learning.translate import Translator
    translator = Translator.load("runs/nv")
    papill = translator.translate(uskin_frames, "uskin", "papillarray")   # (M, 72/3, 3) counts -> (M, 9, 3) N
"""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from unitac_rig.errors import DataError, ModelError, UsageError
from unitac_rig.learning.data import Normaliser
from unitac_rig.learning.engine import UNITAC_GROUP, StackedAutoencoders
from unitac_rig.learning.run import load_run


class Translator:
    """One member of a run's UniTac-NV model, ready for inference (no dropout, CPU by default)."""

    def __init__(
        self,
        engine: StackedAutoencoders,
        normaliser: Normaliser,
        run_dir: Path | None = None,
        frame_baseline: str = "press",
    ) -> None:
        self.engine = engine
        self.normaliser = normaliser
        self.run_dir = run_dir
        self.frame_baseline = frame_baseline  # what the run's frames were referenced to (storage.reader)

    @classmethod
    def load(cls, run_dir: Path | str, member: int = 0, device: str = "cpu") -> Translator:
        run = load_run(Path(run_dir), device)
        run.check_member(member)
        engine = run.engine.member(member, groups=[UNITAC_GROUP])
        return cls(engine, run.normaliser, Path(run_dir), run.config.frame_baseline)

    @property
    def sensors(self) -> tuple[str, ...]:
        return self.engine.sensors

    def _known(self, sensor: str) -> None:
        if sensor not in self.sensors:
            raise ModelError(
                f"this model knows no sensor {sensor!r}", hint=f"it was trained on {', '.join(self.sensors)}"
            )

    def _check(self, sensor: str, frames: np.ndarray) -> np.ndarray:
        """``frames`` as float32; ModelError unless the model knows ``sensor`` and they are its (..., n_taxels, 3)."""
        self._known(sensor)
        frames = np.asarray(frames, dtype=np.float32)
        n_taxels = self.engine.feature_dims[sensor] // 3
        if frames.shape[-2:] != (n_taxels, 3):
            raise ModelError(
                f"{sensor} frames must be (..., {n_taxels}, 3), got {frames.shape}",
                hint="pass tare-subtracted frames in the sensor's own units and layout order",
            )
        return frames

    def encode(self, frames: np.ndarray, sensor: str) -> np.ndarray:
        """The 16-d latents (..., latent) of ``frames`` (..., n_taxels, 3) in sensor units."""
        frames = self._check(sensor, frames)
        flat = self.normaliser.normalise(sensor, frames.reshape(-1, *frames.shape[-2:]))
        z = self.engine.encode(UNITAC_GROUP, sensor, torch.from_numpy(flat))[0].cpu().numpy()
        return z.reshape(*frames.shape[:-2], z.shape[-1])

    def translate(self, frames: np.ndarray, source: str, target: str) -> np.ndarray:
        """``frames`` (..., n_src, 3) in the source's units -> (..., n_dst, 3) in the target's units."""
        self._known(target)
        z = self.encode(frames, source)
        decoded = self.engine.decode(UNITAC_GROUP, torch.from_numpy(z.reshape(-1, z.shape[-1])))[target]
        out = self.normaliser.denormalise(target, decoded[0].cpu().numpy())
        return out.reshape(*z.shape[:-1], *out.shape[-2:])

    def single_frame_latency_ms(self, source: str, target: str, repeats: int = 200) -> dict[str, float]:
        """Wall time of translating one frame (median and 90th percentile over ``repeats`` calls, ms)."""
        n_taxels = self.engine.feature_dims[source] // 3
        frame = np.zeros((n_taxels, 3), dtype=np.float32)
        for _ in range(10):
            self.translate(frame, source, target)
        times = []
        for _ in range(repeats):
            began = time.perf_counter()
            self.translate(frame, source, target)
            times.append((time.perf_counter() - began) * 1e3)
        times.sort()
        return {"median_ms": statistics.median(times), "p90_ms": times[int(0.9 * (len(times) - 1))]}


@dataclass
class FramesInput:
    frames: np.ndarray  # (M, n, 3)
    keys: dict[str, np.ndarray]  # object_id / rotation_deg / angle_deg / target_n when the input has them


def read_frames(path: Path, sensor: str, baseline: str = "press") -> FramesInput:
    """Frames from a session ``.h5`` (its force-matched frames, referenced to ``baseline``: the one the run trained
    on), an ``.npy`` array or an ``.npz`` (key ``frames`` or ``values``, or its only array); shape (M, n_taxels, 3)
    or (n_taxels, 3)."""
    path = Path(path)
    if not path.is_file():
        raise UsageError(f"{path} does not exist")
    suffix = path.suffix.lower()
    if suffix in (".h5", ".hdf5"):
        from unitac_rig.storage.reader import load_matched_set

        matched = load_matched_set(path, baseline)
        if matched.sensor != sensor:
            raise UsageError(
                f"{path.name} was recorded with {matched.sensor}, not {sensor}", hint=f"pass --from {matched.sensor}"
            )
        keys = {
            "object_id": np.full(len(matched.target_n), matched.object_id),
            "rotation_deg": matched.rotation_deg,
            "angle_deg": matched.angle_deg,
            "target_n": matched.target_n,
        }
        return FramesInput(np.asarray(matched.values, dtype=np.float32), keys)
    try:
        if suffix == ".npy":
            array = np.load(path, allow_pickle=False)
        elif suffix == ".npz":
            with np.load(path, allow_pickle=False) as archive:
                names = list(archive.keys())
                key = next((k for k in ("frames", "values") if k in names), names[0] if len(names) == 1 else None)
                if key is None:
                    raise UsageError(f"{path.name} holds {names}; name the frames array 'frames'")
                array = archive[key]
        else:
            raise UsageError(f"cannot read {path.name}", hint="give a session .h5, or frames as .npy / .npz")
    except (OSError, ValueError) as exc:
        raise DataError(f"{path} cannot be read ({exc})") from exc
    array = np.asarray(array, dtype=np.float32)
    if array.ndim == 2:
        array = array[None]
    return FramesInput(array, {})


def translate_file(
    run_dir: Path, source: str, target: str, input_path: Path, output_path: Path | None = None
) -> dict[str, Any]:
    """Translate a file and write ``<input>_to_<target>.npz`` (or ``output_path``); returns a summary."""
    translator = Translator.load(run_dir)
    data = read_frames(input_path, source, translator.frame_baseline)
    translated = translator.translate(data.frames, source, target)
    output_path = (
        Path(output_path) if output_path else Path(input_path).with_name(f"{Path(input_path).stem}_to_{target}.npz")
    )
    arrays = {"frames": translated, "source_sensor": np.array(source), "target_sensor": np.array(target), **data.keys}
    np.savez_compressed(output_path, **arrays)  # type: ignore[arg-type]
    latency = translator.single_frame_latency_ms(source, target)
    return {
        "input": str(input_path),
        "output": str(output_path),
        "frames": int(translated.shape[0]),
        "input_shape": list(data.frames.shape),
        "output_shape": list(translated.shape),
        "mean_abs_per_channel": np.abs(translated).reshape(-1, 3).mean(axis=0).tolist(),
        "latency_ms": latency,
    }

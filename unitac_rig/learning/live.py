"""The trained model on live frames: ``unitac-rig stream`` reads the mounted sensor and emits, per frame, its latent,
the frame translated into every other sensor of the run, and the contact-geometry estimate when the run has one.

:class:`LiveModel` runs one member of a run as the very module ``export-model`` writes
(:class:`unitac_rig.learning.network.UniTacNV`, the normaliser folded in), and the geometry head as the same
:func:`unitac_rig.learning.network.mlp`, under ``torch.inference_mode`` on one thread. That costs torch's per-call
overhead over the numpy layers it replaced (one PapillArray frame's latent, uSkin translation and geometry: 264 us
against 85 us at load 20 on 2 cores), for one forward shared with ``export-model``.

:func:`stream_frames` is the loop: tare on the first frames (the pad unloaded), then for every frame the sensor
delivers (all of them, in order: none is skipped to catch up) one JSON line handed to ``write``, and the latency
from the frame's host timestamp (stamped by the driver when the frame was complete) to the moment ``write``
returned, on the same host clock.

The first lines after the tare are often a backlog (frames queued while the model and the output started): they
carry ``"warmup":true`` until the loop first catches up with the sensor (a poll that found the next frame not yet
stamped when the previous line was written) or :data:`WARMUP_MAX_S` passed, and the summary reports their latency
apart from the steady state's, so p99 and max describe the stream a controller lives with.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import torch
from torch import nn

from drivers.frames import TactileFrame
from unitac_rig.errors import ModelError


@dataclass
class LiveOutput:
    latent: np.ndarray  # (B, latent)
    translated: dict[str, np.ndarray]  # sensor -> (B, n_taxels, 3) in that sensor's units
    geometry_mm: np.ndarray | None  # (B, points) depth profile, mm


class LiveModel:
    """One member of a run, ready for frames of ``sensor`` (tare-subtracted, the sensor's units)."""

    def __init__(self, run_dir: Path, sensor: str, member: int = 0, geometry: bool = True) -> None:
        from unitac_rig.learning.engine import UNITAC_GROUP
        from unitac_rig.learning.export import hub_model
        from unitac_rig.learning.train import load_run

        run = load_run(Path(run_dir))
        engine = run.engine
        run.check_member(member)
        sensors = engine.group(UNITAC_GROUP).sensors
        if sensor not in sensors:
            raise ModelError(
                f"the run was not trained on the mounted sensor {sensor!r}", hint=f"it knows {', '.join(sensors)}"
            )
        self.run_dir = Path(run_dir)
        self.sensor = sensor
        self.member = member
        self.targets = tuple(s for s in sensors if s != sensor)
        self.n_taxels = engine.feature_dims[sensor] // 3
        self.model = hub_model(run, member)
        self.latent_dim = self.model.latent_dim
        self.geometry: nn.Sequential | None = None
        self.geometry_meta: dict[str, Any] | None = None
        if geometry:
            self._load_geometry(run, member)

    def _load_geometry(self, run: Any, member: int) -> None:
        from unitac_rig.learning.contact_geometry import ESTIMATOR_PT, GeometryEstimator

        if not (self.run_dir / ESTIMATOR_PT).is_file():
            return
        estimator = GeometryEstimator.load(self.run_dir)
        estimator.check_fits(run, member)
        chosen = estimator.trained_on(self.sensor)
        self.geometry = estimator.head(chosen)
        self.geometry_meta = {
            "trained_on": chosen,
            "offsets_mm": list(estimator.meta["offsets_mm"]),
            "object": estimator.meta.get("object"),
        }

    def __call__(self, frames: np.ndarray) -> LiveOutput:
        """``frames`` (B, n_taxels, 3) of the mounted sensor -> latents, translations and geometry."""
        x = torch.from_numpy(np.ascontiguousarray(frames, dtype=np.float32))
        with torch.inference_mode():
            latent = self.model.encode(x, self.sensor)
            translated = {t: self.model.decode(latent, t).numpy() for t in self.targets}
            geometry = self.geometry(latent).numpy() if self.geometry is not None else None
        return LiveOutput(latent.numpy(), translated, geometry)


class LiveSensor(Protocol):
    """What the loop needs of a driver (``drivers.sensor_base.PumpedSensor``)."""

    def poll_wait(self, timeout_s: float) -> list[TactileFrame]: ...


WARMUP_MAX_S = 2.0  # the warm-up backlog ends by this long after the first line at the latest, s


def _latency_summary(latencies_ns: list[int]) -> dict[str, Any]:
    ms = sorted(x / 1e6 for x in latencies_ns)

    def pct(p: float) -> float | None:
        return ms[min(len(ms) - 1, int(p * (len(ms) - 1) + 0.5))] if ms else None

    return {
        "median": statistics.median(ms) if ms else None,
        "p90": pct(0.90),
        "p99": pct(0.99),
        "p999": pct(0.999),
        "max": ms[-1] if ms else None,
        "over_1ms": sum(x > 1.0 for x in ms),
    }


@dataclass
class StreamStats:
    """What a stream did: frames in and out, device-counter gaps, and the per-frame latency (host clock, ns), the
    warm-up backlog's apart from the steady state's."""

    frames_in: int = 0  # every frame the driver delivered up to the stop (each is tared on or emitted: none skipped)
    frames_out: int = 0
    tare_frames: int = 0
    seq_gaps: int = 0  # frames the device counted but the host never received (devices with a frame counter)
    latencies_ns: list[int] = field(default_factory=list)  # steady state (after the warm-up)
    warmup_latencies_ns: list[int] = field(default_factory=list)
    started_ns: int = 0  # host stamp of the first line's frame
    steady_ns: int | None = None  # host stamp of the first steady-state frame
    last_frame_ns: int = 0  # host stamp of the last line's frame
    ended_ns: int = 0

    def summary(self) -> dict[str, Any]:
        """Counts, the achieved rate (steady-state frames per second of sensor time) and the latency percentiles."""
        ms = np.asarray(self.latencies_ns) / 1e6
        seconds = (self.ended_ns - self.started_ns) / 1e9
        steady = len(self.latencies_ns)
        span = (self.last_frame_ns - self.steady_ns) / 1e9 if self.steady_ns is not None else 0.0
        warm_end = self.steady_ns if self.steady_ns is not None else self.last_frame_ns
        return {
            "frames_in": self.frames_in,
            "frames_out": self.frames_out,
            "tare_frames": self.tare_frames,
            "seq_gaps": self.seq_gaps,
            "seconds": seconds,
            # frames per second the sensor delivered in the steady state (between the first and the last steady
            # frame's stamps); over the whole stream when it never left the warm-up
            "rate_hz": (steady - 1) / span if span > 0 else (self.frames_out / seconds if seconds > 0 else None),
            "latency_ms": _latency_summary(self.latencies_ns),  # steady state only
            "warmup": {
                "frames": len(self.warmup_latencies_ns),
                "seconds": (warm_end - self.started_ns) / 1e9 if self.frames_out else 0.0,
                "latency_ms": _latency_summary(self.warmup_latencies_ns),
            },
            # 0.05 ms bins up to 5 ms (the last bin holds everything slower), steady state, for a figure
            "histogram_ms": {
                "bin_ms": 0.05,
                "counts": np.bincount(np.minimum((ms / 0.05).astype(int), 100), minlength=101).tolist(),
            },
        }


_FORMATS: dict[tuple[int | bool, ...], str] = {}


def json_numbers(values: np.ndarray) -> str:
    """A 1-D or 2-D array as JSON with 6 significant digits (float32 carries about 7), about 4x faster than
    ``json.dumps(values.tolist())``; a non-finite number becomes null."""
    array = np.asarray(values)
    finite = bool(np.isfinite(array).all())
    key = (*array.shape, finite)
    template = _FORMATS.get(key)
    if template is None:
        row = "[" + ",".join(["%.6g" if finite else "%s"] * array.shape[-1]) + "]"
        template = row if array.ndim == 1 else "[" + ",".join([row] * array.shape[0]) + "]"
        _FORMATS[key] = template
    numbers = array.reshape(-1).tolist()
    if finite:
        return template % tuple(numbers)
    return template % tuple(f"{x:.6g}" if np.isfinite(x) else "null" for x in numbers)


def frame_line(
    index: int,
    frame: TactileFrame,
    output: LiveOutput,
    row: int,
    model: LiveModel,
    now_ns: int,
    *,
    tared: np.ndarray | None = None,
    epoch_offset_ns: int = 0,
    warmup: bool = False,
) -> bytes:
    """One JSON line: the frame's identity, its host time (monotonic ``host_t_ns``, and ``unix_t_ns``: the same
    instant on the wall clock, ``host_t_ns + epoch_offset_ns``), whether it is warm-up backlog, the tared frame the
    model saw (``frame``, the sensor's units), its latent, its translations, its geometry, and the latency up to
    building this line (ms; the stats also count writing it)."""
    translated = ",".join(f'"{t}":{json_numbers(v[row])}' for t, v in output.translated.items())
    geometry = "" if output.geometry_mm is None else f',"geometry_mm":{json_numbers(output.geometry_mm[row])}'
    raw = "" if tared is None else f',"frame":{json_numbers(tared)}'
    seq = "null" if frame.seq is None else str(int(frame.seq))
    return (
        f'{{"i":{index},"sensor":"{model.sensor}","host_t_ns":{frame.host_t_ns},'
        f'"unix_t_ns":{frame.host_t_ns + epoch_offset_ns},"seq":{seq},'
        f'"valid":{"true" if frame.valid else "false"},"warmup":{"true" if warmup else "false"}{raw},'
        f'"latent":{json_numbers(output.latent[row])},'
        f'"translated":{{{translated}}}{geometry},"latency_ms":{(now_ns - frame.host_t_ns) / 1e6:.4f}}}\n'
    ).encode()


def _count_seq_gaps(frames: Sequence[TactileFrame], last_seq: int | None) -> tuple[int, int | None]:
    """Frames lost between consecutive sequence numbers (frames without one count none), and the last one seen."""
    gaps = 0
    for frame in frames:
        if frame.seq is not None:
            if last_seq is not None and frame.seq > last_seq + 1:
                gaps += frame.seq - last_seq - 1
            last_seq = frame.seq
    return gaps, last_seq


def stream_frames(
    sensor: LiveSensor,
    model: LiveModel,
    write: Callable[[bytes], None],
    *,
    tare_frames: int = 50,
    max_frames: int | None = None,
    duration_s: float | None = None,
    should_stop: Callable[[], bool] = lambda: False,
    clock_ns: Callable[[], int] = time.monotonic_ns,
) -> StreamStats:
    """Tare on the first ``tare_frames`` valid frames (median, as a press's tare), then emit every frame until
    ``max_frames`` were emitted, ``duration_s`` passed since the first emitted frame, or ``should_stop()``.

    Runs torch on one thread: layers this small gain nothing from more, and on a busy 2-core box two threads made a
    10-frame batch 50x slower (17 ms against 0.36 ms, load 20).

    ``clock_ns`` is the clock of the frames' ``host_t_ns`` (the drivers stamp with ``time.monotonic_ns``); its
    offset to the wall clock is measured once here, so ``unix_t_ns`` never jumps when the wall clock is stepped."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        epoch_offset_ns = time.time_ns() - clock_ns()
        stats = StreamStats()
        warm = True  # in the warm-up backlog until the loop catches up (see the module's docstring)
        tare: list[np.ndarray] = []
        baseline: np.ndarray | None = None
        last_seq: int | None = None
        deadline_ns: int | None = None
        while not should_stop():
            frames = sensor.poll_wait(0.1)
            if not frames:
                continue
            if max_frames is not None and baseline is not None:
                frames = frames[: max_frames - stats.frames_out]  # the rest arrived after the stop: not dropped
            stats.frames_in += len(frames)
            gaps, last_seq = _count_seq_gaps(frames, last_seq)
            stats.seq_gaps += gaps
            if baseline is None:
                take = frames[: max(0, tare_frames - len(tare))]
                tare += [f.values for f in take if f.valid]
                stats.tare_frames += len(take)
                frames = frames[len(take) :]
                if len(tare) >= tare_frames or (stats.tare_frames >= tare_frames and tare):
                    baseline = np.median(np.stack(tare), axis=0).astype(np.float32)
                if not frames or baseline is None:
                    continue
                if max_frames is not None and len(frames) > max_frames:
                    stats.frames_in -= len(frames) - max_frames
                    frames = frames[:max_frames]
            values = np.stack([f.values for f in frames]).astype(np.float32) - baseline
            if (
                warm
                and stats.frames_out
                and (
                    frames[0].host_t_ns > stats.ended_ns or frames[0].host_t_ns - stats.started_ns > WARMUP_MAX_S * 1e9
                )
            ):
                warm = False  # the next frame was stamped after the last line was written: no backlog left
                stats.steady_ns = frames[0].host_t_ns
            output = model(values)
            for row, frame in enumerate(frames):
                line = frame_line(
                    stats.frames_out,
                    frame,
                    output,
                    row,
                    model,
                    clock_ns(),
                    tared=values[row],
                    epoch_offset_ns=epoch_offset_ns,
                    warmup=warm,
                )
                write(line)
                done_ns = clock_ns()
                (stats.warmup_latencies_ns if warm else stats.latencies_ns).append(done_ns - frame.host_t_ns)
                if stats.frames_out == 0:
                    stats.started_ns = frame.host_t_ns
                    if duration_s is not None:
                        deadline_ns = frame.host_t_ns + round(duration_s * 1e9)
                stats.frames_out += 1
                stats.last_frame_ns = frame.host_t_ns
                stats.ended_ns = done_ns
            if max_frames is not None and stats.frames_out >= max_frames:
                break
            if deadline_ns is not None and stats.ended_ns >= deadline_ns:
                break
    finally:
        torch.set_num_threads(threads)
    return stats


class _PolledSensor:
    """A driver without ``poll_wait`` (not a :class:`drivers.sensor_base.PumpedSensor`): polled every 0.2 ms."""

    def __init__(self, sensor: Any) -> None:
        self._sensor = sensor

    def poll_wait(self, timeout_s: float) -> list[TactileFrame]:
        deadline = time.monotonic() + timeout_s
        while True:
            frames = list(self._sensor.poll())
            if frames or time.monotonic() >= deadline:
                return frames
            time.sleep(0.0002)


def live_sensor(sensor: Any) -> LiveSensor:
    """``sensor`` itself when it can wait for frames (every driver of this package), else a polling adapter."""
    return sensor if callable(getattr(sensor, "poll_wait", None)) else _PolledSensor(sensor)

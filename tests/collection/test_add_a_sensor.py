"""Adding a sensor is one spec and one registry line: a made-up 2x2 force skin, defined in this file only, goes through
everything a real sensor does. It is collected on the fast twin and on the real-time twin (the hardware code path
over loopback TCP), trained on with the PapillArray, translated, given to the contact-geometry task, rendered in the
synthetic contacts and probed (simulated and over its wire), with no file of the package edited.

Its wire is a test-only one (one JSON line of 12 numbers, N, per sample, over TCP), its pad model the generic force
model the simulator has for any layout in newtons (``sim.sensor_models.model_for``). Loopback addresses
127.0.0.140-149 belong to these tests.
"""

from __future__ import annotations

import contextlib
import json
import select
import socket
import threading
import time
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal
from urllib.parse import urlsplit

import numpy as np
import pytest
from pydantic import Field

from drivers.clock import Clock, MonotonicClock
from drivers.frames import TactileFrame
from drivers.layouts import SensorLayout
from drivers.sensor import TactileSensor, TareRecord
from drivers.sensor_base import PumpedSensor
from tests.helpers import cli
from unitac_rig.learning.synthetic_data import synthetic_matched_sets
from unitac_rig.rig.objects import get_object
from unitac_rig.rig.sensors import SENSORS, SensorConfigBase, SensorSpec, SyntheticResponse
from unitac_rig.sim.fast_rig import SimRig, seeded_scene
from unitac_rig.sim.sensor_models import model_for
from unitac_rig.sim.sensor_signals import SensorSample, SignalSource
from unitac_rig.sim.twin import first_free_loopback
from unitac_rig.storage.reader import load_matched_set
from unitac_rig.storage.recorder import session_path

TINY = SensorLayout(
    name="tinyskin",
    model="Tiny 2x2 test skin",
    rows=2,
    cols=2,
    pitch_mm=7.0,
    units="N",
    has_displacement=False,
    description="a made-up 2x2 three-axis force skin that exists only in this test",
)


class TinyTcpConfig(SensorConfigBase):
    """``[sensors.tinyskin]``: where its TCP stream is."""

    type: Literal["tinyskin-tcp"] = "tinyskin-tcp"
    url: str = Field(description="The sensor's stream, tcp://HOST:PORT.")
    rate_hz: int = Field(100, ge=1, le=1000, description="Samples a second the device sends.")


# ---- its driver: one PumpedSensor, fed by its TCP stream (hardware, the real-time twin) or by the fast twin ----------


class TinyDriver(PumpedSensor):
    """Streams the frames its link hands over: ``url`` (tcp://HOST:PORT, one JSON line per sample) or, on the fast
    twin, ``feed`` sampled at ``rate_hz`` on the driver's (virtual) clock."""

    def __init__(
        self, clock: Clock, *, url: str | None = None, feed: SignalSource | None = None, rate_hz: int = 100
    ) -> None:
        super().__init__(
            TINY, clock=clock, stall_timeout_s=1.0, thread_name="tinyskin", is_saturated=lambda v: np.zeros(len(v))
        )
        self.url, self.feed, self.period_ns = url, feed, round(1e9 / rate_hz)
        self._socket: socket.socket | None = None
        self._buffer = b""
        self._next_ns = 0

    def _open(self) -> None:
        if self.url is not None:
            address = urlsplit(self.url)
            self._socket = socket.create_connection((address.hostname, address.port), timeout=2.0)
            self._socket.setblocking(False)
        self._next_ns = self.clock.now_ns()

    def _close(self) -> None:
        if self._socket is not None:
            self._socket.close()
            self._socket = None

    def _pump(self, wait_s: float) -> list[TactileFrame]:
        rows = self._read_socket(wait_s) if self._socket is not None else self._read_feed(wait_s)
        now_ns = self.clock.now_ns()
        return [TactileFrame(sensor=TINY.name, host_t_ns=now_ns, values=row.reshape(TINY.frame_shape)) for row in rows]

    def _read_socket(self, wait_s: float) -> list[np.ndarray]:
        assert self._socket is not None
        if select.select([self._socket], [], [], max(wait_s, 0.0))[0]:
            chunk = self._socket.recv(65536)
            if not chunk:
                raise ConnectionError("tinyskin: the device closed the stream")
            self._buffer += chunk
        *lines, self._buffer = self._buffer.split(b"\n")
        return [np.asarray(json.loads(line), dtype=np.float64) for line in lines if line.strip()]

    def _read_feed(self, wait_s: float) -> list[np.ndarray]:
        assert self.feed is not None
        rows = []
        while self._next_ns <= self.clock.now_ns():
            rows.append(np.asarray(self.feed.sample(self._next_ns).values, dtype=np.float64).reshape(-1))
            self._next_ns += self.period_ns
        if not rows and wait_s > 0 and isinstance(self.clock, MonotonicClock):
            time.sleep(min(wait_s, 0.005))
        return rows

    def tare(self, frames: list[TactileFrame]) -> TareRecord:
        values = np.stack([f.values for f in frames])
        return TareRecord(
            values.mean(axis=0), len(frames), self.clock.now_ns(), "host-mean", float(values.std(axis=0).max())
        )


def open_tiny(config: SensorConfigBase, clock: Clock) -> TactileSensor:
    assert isinstance(config, TinyTcpConfig)
    return TinyDriver(clock, url=config.url, rate_hz=config.rate_hz)


# ---- its device: the same JSON lines, served in real time from whatever a signal source says -----------------------


class TinyDevice:
    """The sensor's device on TCP: a JSON line of its 12 readings (N) per sample, at ``rate_hz``, to every client."""

    def __init__(self, host: str, port: int, source: SignalSource, rate_hz: int = 100) -> None:
        self.source, self.period_s = source, 1.0 / rate_hz
        self._listener = socket.create_server((host, port))
        self.url = f"tcp://{host}:{self._listener.getsockname()[1]}"
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="tinyskin-device", daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        clients: list[socket.socket] = []
        due = time.monotonic()
        while not self._stop.is_set():
            if select.select([self._listener], [], [], max(0.0, min(due - time.monotonic(), 0.05)))[0]:
                clients.append(self._listener.accept()[0])
            if time.monotonic() < due:
                continue
            due = max(due + self.period_s, time.monotonic() - 1.0)
            line = json.dumps(np.asarray(self.source.sample(time.monotonic_ns()).values).ravel().tolist()) + "\n"
            for client in list(clients):
                try:
                    client.sendall(line.encode())
                except OSError:
                    clients.remove(client)
                    client.close()
        for client in clients:
            client.close()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        self._listener.close()

    def __enter__(self) -> TinyDevice:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class RampSource:
    """A slow press for ``probe --simulated``: all taxels load together, 0..2 N each over a second."""

    def sample(self, t_ns: int) -> SensorSample:
        load = 2.0 * ((t_ns / 1e9) % 1.0)
        return SensorSample(values=np.tile([0.0, 0.0, load], (TINY.n_taxels, 1)))


@dataclass(frozen=True)
class TinySimulated:
    """Its simulated side: the fast twin, the real-time twin and probe --simulated (sim/fast_sensors.py's shape)."""

    rng_stream: int = 9  # no other sensor's stream (arm 1, uSkin 2, PapillArray 3, scenes 4, placements 5)
    rate_hz: int = 100
    twin_port: int = 30140

    def model(self, rng: np.random.Generator) -> Any:
        return model_for(TINY, rng)  # the simulator's generic force model, for any layout in newtons

    def open(self, rig: SimRig, feed: SignalSource) -> TactileSensor:
        return TinyDriver(rig.clock, feed=feed, rate_hz=self.rate_hz)

    def serve_twin(self, host: str, source: SignalSource, serve: Any) -> None:
        serve(TinyDevice(host, self.twin_port, source, self.rate_hz))

    def twin_table(self, host: str) -> str:
        return f'type = "tinyskin-tcp"\nurl = "tcp://{host}:{self.twin_port}"\nrate_hz = {self.rate_hz}\n'

    def probe(self, options: Mapping[str, Any], stack: contextlib.ExitStack) -> TactileSensor:
        device = stack.enter_context(TinyDevice("127.0.0.1", 0, RampSource(), int(options.get("rate_hz", 100))))
        return TinyDriver(MonotonicClock(), url=device.url, rate_hz=int(options.get("rate_hz", 100)))


TINY_SIMULATED = TinySimulated()
SPEC = SensorSpec(
    layout=TINY,
    config_types=(TinyTcpConfig,),
    open_driver=open_tiny,
    simulated=f"{__name__}:TINY_SIMULATED",
    pad="pillars",
    geometry_dropout=0.25,
    synthetic=SyntheticResponse(gain_normal=2.0, gain_shear=2.0, noise=0.0),
)


# ---- the tests ----------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def registered() -> Iterator[SensorSpec]:
    """The registry line, and nothing else."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setitem(SENSORS, TINY.name, SPEC)
        yield SPEC


@pytest.fixture(scope="module")
def data(registered: SensorSpec, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Both sensors on the fast twin: the object the model trains on and the unseen one the geometry task uses."""
    directory = tmp_path_factory.mktemp("tiny") / "data"
    for object_id, angles in (("circle_pla", "5"), ("irregular_pla", "3")):
        for sensor in ("tinyskin", "papillarray"):
            assert (
                cli(
                    [
                        "collect",
                        "--object",
                        object_id,
                        "--sensor",
                        sensor,
                        "--angles",
                        angles,
                        "--data",
                        str(directory),
                        "--no-live",
                    ]
                )
                == 0
            )
    return directory


@pytest.fixture(scope="module")
def run(data: Path) -> Path:
    out = data.parent / "run"
    assert cli(["train", "--data", str(data), "--out", str(out), "--epochs", "3", "--no-report"]) == 0
    return out


def test_the_fast_twin_collects_it_with_its_pad_model(data: Path) -> None:
    matched = load_matched_set(session_path(data, "circle_pla", "tinyskin"))
    assert matched.values.shape[1:] == TINY.frame_shape
    assert 2.0 < float(matched.values[..., 2].sum(axis=1).max()) < 12.0  # a few newtons on the pad at 4..10 N
    assert seeded_scene(get_object("circle_pla"), 0.0, "tinyskin", seed=0).kind == "pillars"  # the spec's pad


def test_train_translate_and_geometry_take_it_like_any_sensor(data: Path, run: Path) -> None:
    assert (
        cli(
            [
                "translate",
                str(run),
                str(session_path(data, "circle_pla", "tinyskin")),
                "--from",
                "tinyskin",
                "--to",
                "papillarray",
            ]
        )
        == 0
    )
    translated = np.load(run / "translations" / "circle_pla__tinyskin_to_papillarray.npz")
    assert translated["frames"].shape[1:] == (9, 3) and np.isfinite(translated["frames"]).all()

    assert cli(["geometry", str(run), "--epochs", "2"]) == 0
    geometry = json.loads((run / "geometry.json").read_text())
    assert {"tinyskin_to_tinyskin", "tinyskin_to_papillarray"} <= set(geometry["scenarios"])
    assert all(np.isfinite(s["mae_mm"]) for s in geometry["scenarios"].values())
    estimator = json.loads((run / "geometry_estimator.json").read_text())
    assert estimator["dropout"]["tinyskin"] == SPEC.geometry_dropout  # the head's dropout comes from the spec


def test_the_real_time_twin_serves_it_to_the_hardware_code_path(registered: SensorSpec, tmp_path: Path) -> None:
    from unitac_rig.sim.twin.rig import RigTwin

    with RigTwin("circle_pla", sensor="tinyskin", host=first_free_loopback(140, 149), seed=3) as twin:
        rig_file = tmp_path / "twin.toml"
        rig_file.write_text(twin.rig_file())
        assert (
            cli(
                [
                    "collect",
                    "--rig",
                    str(rig_file),
                    "--object",
                    "circle_pla",
                    "--sensor",
                    "tinyskin",
                    "--angles",
                    "2",
                    "--data",
                    str(tmp_path / "data"),
                    "--no-live",
                ]
            )
            == 0
        )
    matched = load_matched_set(session_path(tmp_path / "data", "circle_pla", "tinyskin"))
    assert matched.values.shape[1:] == TINY.frame_shape and len(matched) > 0
    assert 2.0 < float(matched.values[..., 2].sum(axis=1).max()) < 12.0  # the twin's scene, felt through TCP


def test_synthetic_contacts_read_it_through_its_spec(registered: SensorSpec) -> None:
    (matched,) = synthetic_matched_sets(("circle_pla",), (TINY,), angles_deg=(0.0, 20.0), targets_n=(4.0, 8.0))
    normal = matched.values[..., 2].sum(axis=1)
    np.testing.assert_allclose(normal, SPEC.synthetic.gain_normal * matched.force_n, rtol=1e-5)  # no noise


def test_probe_reads_it_simulated_and_over_its_wire(registered: SensorSpec, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli(["probe", "tinyskin", "--simulated", "--json", "--frames", "3"]) == 0
    records = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [(r["sensor"], len(r["values"]), r["units"]) for r in records] == [("tinyskin", 4, "N")] * 3

    with TinyDevice("127.0.0.1", 0, RampSource()) as device:  # "hardware": its options are its rig-file fields
        assert cli(["probe", "tinyskin", "--url", device.url, "--rate-hz", "100", "--frames", "2"]) == 0
    assert "Tiny 2x2 test skin" in capsys.readouterr().out
    assert cli(["probe", "tinyskin"]) == 2
    assert "probe tinyskin needs --url" in capsys.readouterr().err

"""A third sensor added through the sensor registry alone: the rig file, the hardware rig, the simulated rig, sensor
choice and a recorded session all pick it up, with no other file edited."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path
from typing import Literal

import numpy as np
import pytest

from drivers.clock import Clock
from drivers.frames import TactileFrame
from drivers.layouts import SensorLayout
from drivers.sensor import TactileSensor, TareRecord
from drivers.sensor_base import PumpedSensor
from tests.helpers import cli
from unitac_rig.collection.sensor_choice import choose_sensor, collection_order
from unitac_rig.errors import ConfigError, UsageError
from unitac_rig.rig.config import parse_rig_config
from unitac_rig.rig.hardware import HardwareRig
from unitac_rig.rig.sensors import SENSORS, SensorConfigBase, SensorSpec
from unitac_rig.sim.fast_rig import SimRig
from unitac_rig.sim.scene import TaxelLoads
from unitac_rig.sim.sensor_signals import SensorSample, SignalSource
from unitac_rig.storage.reader import load_matched_set
from unitac_rig.storage.recorder import session_path
from unitac_rig.storage.summary import inspect_dataset

FAKE = SensorLayout(
    name="fakeskin",
    model="Fake 2x3 skin",
    rows=2,
    cols=3,
    pitch_mm=8.0,
    units="N",
    has_displacement=False,
    description="a made-up 2x3 force-reading skin, to prove a sensor is one module and one registry entry",
)
PERIOD_NS = 10_000_000  # 100 Hz

# a real arm needs its TCP and payload in the rig file (what the pendant says)
ARM = {"host": "10.0.0.2", "tcp_offset": [0.0, 0.0, 0.1, 0.0, 0.0, 0.0], "payload_kg": 0.3}


class FakeUsbConfig(SensorConfigBase):
    type: Literal["fakeskin-usb"] = "fakeskin-usb"
    port: str


class FakeDriver(PumpedSensor):
    """A fake, not a mock: streams what its signal source reads, at 100 Hz on the driver's clock."""

    def __init__(self, source: SignalSource, clock: Clock) -> None:
        super().__init__(
            FAKE, clock=clock, stall_timeout_s=0.5, thread_name="fakeskin", is_saturated=lambda v: np.zeros(len(v))
        )
        self.source = source
        self._next_ns = 0

    def _open(self) -> None:
        self._next_ns = self.clock.now_ns()

    def _close(self) -> None:
        pass

    def _pump(self, wait_s: float) -> list[TactileFrame]:
        now_ns = self.clock.now_ns()
        frames = []
        while self._next_ns <= now_ns:
            values = np.asarray(self.source.sample(self._next_ns).values, dtype=np.float64)
            frames.append(TactileFrame(sensor=FAKE.name, host_t_ns=now_ns, values=values))
            self._next_ns += PERIOD_NS
        if not frames and wait_s > 0:
            time.sleep(min(wait_s, 0.005))
        return frames

    def tare(self, frames: list[TactileFrame]) -> TareRecord:
        values = np.stack([f.values for f in frames])
        spread = float(values.std(axis=0).max())
        return TareRecord(values.mean(axis=0), len(frames), self.clock.now_ns(), "host-mean", spread)


class RestingSource:
    def sample(self, t_ns: int) -> SensorSample:
        return SensorSample(values=np.zeros(FAKE.frame_shape))


OPENED: list[SensorConfigBase] = []  # what the driver factory was called with


def open_fake(config: SensorConfigBase, clock: Clock) -> TactileSensor:
    OPENED.append(config)
    return FakeDriver(RestingSource(), clock)


class FakeModel:
    """Taxel loads (N) straight through, with a little noise."""

    layout = FAKE

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng

    def sample(self, loads: TaxelLoads, t_ns: int) -> SensorSample:
        """The reading at device time ``t_ns`` (ns; this model has no memory, so it ignores it)."""
        return SensorSample(values=np.asarray(loads.forces_n) + self.rng.normal(0.0, 0.01, FAKE.frame_shape))


class FakeSimulated:
    rng_stream = 9

    def model(self, rng: np.random.Generator) -> FakeModel:
        return FakeModel(rng)

    def open(self, rig: SimRig, feed: SignalSource) -> TactileSensor:
        return FakeDriver(feed, rig.clock)


FAKE_SIMULATED = FakeSimulated()
SPEC = SensorSpec(
    layout=FAKE, config_types=(FakeUsbConfig,), open_driver=open_fake, simulated=f"{__name__}:FAKE_SIMULATED"
)


@pytest.fixture
def fakeskin(monkeypatch: pytest.MonkeyPatch) -> Iterator[SensorSpec]:
    """The registry entry, and nothing else: every other file stays as it is."""
    monkeypatch.setitem(SENSORS, FAKE.name, SPEC)
    OPENED.clear()
    yield SPEC


def test_the_rig_file_accepts_its_table_only_once_registered(fakeskin: SensorSpec) -> None:
    data = {"arm": ARM, "sensors": {"fakeskin": {"type": "fakeskin-usb", "port": "/dev/fake0"}}}
    config = parse_rig_config(data)
    assert isinstance(config.sensors["fakeskin"], FakeUsbConfig)
    assert parse_rig_config(config.model_dump(mode="json")) == config  # the table's own fields survive a dump
    with pytest.raises(ConfigError, match="type 'fakeskin-usb' does not fit sensor 'uskin'"):
        parse_rig_config({"sensors": {"uskin": {"type": "fakeskin-usb", "port": "x"}}})
    with pytest.raises(ConfigError, match=r"sensors\.fakeskin\.baud: unknown key"):
        parse_rig_config({"sensors": {"fakeskin": {"type": "fakeskin-usb", "port": "x", "baud": 9600}}})
    del SENSORS[FAKE.name]
    with pytest.raises(ConfigError, match="'fakeskin-usb' found using 'type' does not match any of the expected tags"):
        parse_rig_config(data)


def test_the_hardware_rig_opens_it_with_the_registered_driver_factory(fakeskin: SensorSpec) -> None:
    config = parse_rig_config({"arm": ARM, "sensors": {"fakeskin": {"type": "fakeskin-usb", "port": "/dev/fake0"}}})
    rig = HardwareRig(config)
    sensor = rig.open_sensor("fakeskin")
    try:
        assert isinstance(sensor, FakeDriver)
        frames = sensor.wait_frames(3, timeout_s=5.0)  # the reader thread the rig started
        assert [f.values.shape for f in frames] == [FAKE.frame_shape] * 3
    finally:
        sensor.disconnect()
        rig.close()
    assert [config.sensors["fakeskin"]] == OPENED  # the factory got the rig file's table


def test_the_simulated_rig_mounts_it_and_a_session_records_its_frames(fakeskin: SensorSpec, tmp_path: Path) -> None:
    with SimRig(parse_rig_config({"press": {"angle_count": 2}}), seed=0) as rig:
        assert collection_order(rig) == ["uskin", "papillarray", "fakeskin"]
        assert choose_sensor(rig, "hex_tpu", "fakeskin", tmp_path).name == "fakeskin"
    assert not cli(
        [
            "collect",
            "--object",
            "hex_tpu",
            "--sensor",
            "fakeskin",
            "--data",
            str(tmp_path),
            "--angles",
            "2",
            "--no-live",
        ]
    )
    (session,) = inspect_dataset(tmp_path)["sessions"]
    assert (session["sensor"], session["presses_complete"]) == ("fakeskin", 2)
    matched = load_matched_set(session_path(tmp_path, "hex_tpu", "fakeskin"))
    assert matched.values.shape[1:] == FAKE.frame_shape
    # the fake reads the scene's taxel loads in N: at the 4..10 N targets the pad carries a few newtons in total
    assert 2.0 < float(matched.values[..., 2].sum(axis=1).max()) < 12.0


def test_a_simulated_collect_mounts_it_after_the_other_sensors_are_complete(
    fakeskin: SensorSpec, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for expected in ("uskin", "papillarray", "fakeskin"):
        assert not cli(["collect", "--object", "circle_pla", "--data", str(tmp_path), "--angles", "1", "--no-live"])
        assert f"mounting {expected}" in capsys.readouterr().out


def test_simulation_options_are_each_sensors_own_and_a_wrong_one_is_named() -> None:
    """The fast twin takes each sensor's options by name (its simulated side's fields), not as rig arguments."""
    config = parse_rig_config({"press": {"angle_count": 2}})
    with SimRig(config, seed=0, sensor_options={"papillarray": {"rate_hz": 1000}}) as rig:
        sensor = rig.open_sensor("papillarray")
        try:
            assert sensor.rate_hz == 1000  # type: ignore[attr-defined]
            frames: list[TactileFrame] = []
            while len(frames) < 20:  # the arm's control period advances the virtual clock
                rig.arm.wait_period()
                frames += sensor.poll()
            spacing_us = np.diff([f.device_t_us for f in frames])
            assert np.median(spacing_us) == pytest.approx(1000, rel=0.05)  # 1 kHz on the device clock
        finally:
            sensor.disconnect()
    with pytest.raises(UsageError, match="the simulated uskin has no option 'rate_hz'") as error:
        SimRig(config, sensor_options={"uskin": {"rate_hz": 1000}})
    assert "transport" in (error.value.hint or "")
    with pytest.raises(UsageError, match="unknown uSkin transport 'usb'"):
        SimRig(config, sensor_options={"uskin": {"transport": "usb"}})
    with pytest.raises(UsageError, match="unknown sensor 'gelsight'"):
        SimRig(config, sensor_options={"gelsight": {}})

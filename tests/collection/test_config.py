"""The rig file: strict validation that names the field, defaults that mean the simulated rig, user objects."""

from pathlib import Path

import pytest

from unitac_rig.errors import ConfigError
from unitac_rig.rig.config import load_rig_config, parse_rig_config
from unitac_rig.rig.objects import get_object

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def test_no_rig_file_is_the_simulated_rig_with_the_papers_procedure():
    config = load_rig_config(None)
    assert config.simulated
    angles = config.angles_deg()
    assert len(angles) == 91 and angles[0] == -45.0 and angles[-1] == 45.0 and angles[46] == 1.0
    assert config.press.threshold_n == 10.0


def test_example_rig_file_is_valid_and_real():
    config = load_rig_config(EXAMPLES / "rig.toml")
    assert not config.simulated
    assert config.sensors["uskin"].type == "uskin-can"
    assert config.sensors["papillarray"].port == "/dev/ttyACM0"


@pytest.mark.parametrize(
    ("data", "expected"),
    [
        ({"press": {"threshhold_n": 3}}, "press.threshhold_n: unknown key"),
        ({"limits": {"hard_force_n": 9}}, "limits.hard_force_n = 9.0 must be above press.threshold_n"),
        ({"press": {"speed_mm_s": 500}}, "press.speed_mm_s = 500.0 exceeds limits.max_speed_mm_s"),
        ({"press": {"strategy": "yolo"}}, "press.strategy"),
        ({"sensors": {"uskin": {"type": "papillarray", "port": "x"}}}, "sensors.uskin: type 'papillarray'"),
        ({"sensors": {"gelsight": {"type": "papillarray", "port": "x"}}}, "sensors.gelsight: unknown sensor id"),
        ({"arm": {"host": "10.0.0.2"}}, "no [sensors.*]"),
        ({"limits": {"workspace_min_m": [0, 0, 1], "workspace_max_m": [1, 1, 0.5]}}, "workspace_min_m"),
    ],
)
def test_bad_rig_files_name_the_field(data, expected):
    with pytest.raises(ConfigError) as err:
        parse_rig_config(data, source="rig.toml")
    assert expected in err.value.one_line()
    assert err.value.one_line().startswith("rig.toml: ")


def test_malformed_toml_and_missing_file(tmp_path: Path):
    bad = tmp_path / "rig.toml"
    bad.write_text("[press\nthreshold_n = 10")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_rig_config(bad)
    with pytest.raises(ConfigError, match="does not exist"):
        load_rig_config(tmp_path / "nope.toml")


def test_user_object_files_resolve_relative_to_the_rig_file():
    config = load_rig_config(EXAMPLES / "sim-with-triangle.toml")
    assert config.simulated
    tri = get_object("tri_tpu", extra_files=config.object.objects_files)
    assert tri.material == "TPU" and len(tri.outer_mm) == 3


def test_the_paper_pace_example_is_the_simulated_rig_resting_before_each_press():
    config = load_rig_config(EXAMPLES / "paper-pace.toml")
    assert config.simulated and config.press.rest_s == 8.0
    assert config.press.threshold_n == 10.0 and len(config.angles_deg()) == 91  # the paper's procedure otherwise

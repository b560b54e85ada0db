"""``unitac-rig probe ur5e``: JSON lines from a simulated controller, one error line for an unreachable host."""

from __future__ import annotations

import json

import pytest
import typer
from typer.testing import CliRunner

from drivers.errors import DeviceNotFound
from unitac_rig.cli import main
from unitac_rig.cli.probe_ur5e import register_ur5e


def probe_app() -> typer.Typer:
    app = typer.Typer()
    register_ur5e(app)

    @app.command("other")
    def _other() -> None:  # a second command keeps typer from flattening the app into its only command
        pass

    return app


def test_simulated_probe_prints_one_json_object_per_state() -> None:
    result = CliRunner().invoke(probe_app(), ["ur5e", "--simulated", "--frames", "3", "--json"])
    assert result.exit_code == 0, result.output
    records = [json.loads(line) for line in result.output.splitlines()]
    assert len(records) == 3
    for record in records:
        assert record["sensor"] == "ur5e" and record["seq"] is None
        assert record["tcp_pose"] == [-0.15, 0.52, 0.25, 0.0, 2.2214, -2.2214]
        assert record["tcp_force"] == [0.0] * 6
        assert record["robot_mode"] == 7 and record["protective_stop"] is False
    assert records[0]["t"] < records[1]["t"] < records[2]["t"]
    assert records[0]["controller_t"] < records[1]["controller_t"] < records[2]["controller_t"]


def test_readable_lines_show_mm_and_newtons() -> None:
    result = CliRunner().invoke(probe_app(), ["ur5e", "--simulated", "--frames", "1"])
    assert result.exit_code == 0, result.output
    assert "-150.00" in result.output and "520.00" in result.output and "mode=7" in result.output


def test_unreachable_host_is_device_not_found() -> None:
    result = CliRunner().invoke(probe_app(), ["ur5e", "--host", "127.0.0.254"])
    assert isinstance(result.exception, DeviceNotFound)


def test_unreachable_host_ends_with_one_line_and_status_1(capfd: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as excinfo:
        main(["probe", "ur5e", "--host", "127.0.0.254"])
    assert excinfo.value.code == 1
    err = capfd.readouterr().err  # file-descriptor level: ur_rtde's own C++ prints would show up here
    assert err.count("\n") == 1 and err.startswith("error: no UR controller answers RTDE at 127.0.0.254")


def test_missing_host_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as excinfo:
        main(["probe", "ur5e"])
    assert excinfo.value.code == 2
    assert "--host" in capsys.readouterr().err

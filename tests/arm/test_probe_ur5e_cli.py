"""``unitac-rig probe ur5e``: JSON lines from a simulated controller, one error line for an unreachable host."""

from __future__ import annotations

import json

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from drivers.arm import ArmState
from drivers.clock import VirtualClock
from drivers.errors import DeviceNotFound
from tests.helpers import cli
from unitac_rig.cli import main
from unitac_rig.cli.probe_ur5e import register_ur5e, run_sign_check, sign_check_verdict
from unitac_rig.errors import UsageError
from unitac_rig.sim.scene import press_pose
from unitac_rig.sim.twin import SceneSpec, start_twin_on_free_loopback

STILL_POSE = np.array([-0.15, 0.52, 0.25, 0.0, 2.2214, -2.2214])  # pad facing base +y: tool z = +y


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
        assert np.linalg.norm(record["tcp_force"][:3]) < 15.0  # nothing touches the pad: the wrist's bias and noise
        assert record["robot_mode"] == 7 and record["protective_stop"] is False
    assert records[0]["t"] < records[1]["t"] < records[2]["t"]
    assert records[0]["controller_t"] < records[1]["controller_t"] < records[2]["controller_t"]


def test_readable_lines_show_mm_and_newtons() -> None:
    result = CliRunner().invoke(probe_app(), ["ur5e", "--simulated", "--frames", "1"])
    assert result.exit_code == 0, result.output
    assert "-150.00" in result.output and "520.00" in result.output and "mode 7" in result.output


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


CENTER = (-0.15, 0.625)
PAD = press_pose(0.0, 33.0, object_center_m=CENTER, height_m=0.20)  # 8 mm clear of circle_pla (radius 25 mm)


@pytest.mark.parametrize(("ft_sign", "ok"), [(1.0, True), (-1.0, False)])
def test_sign_check_passes_a_push_toward_the_flange_and_refuses_a_reversed_sign(
    ft_sign: float, ok: bool, capfd: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The object pushes the pad back toward the flange (the twin moves it 8.5 mm toward the pad: about 12 N) once
    the operator is asked to push; a wrist with a flipped frame (``ft_sign`` -1) must be refused."""
    echo = typer.echo
    scene = SceneSpec("circle_pla", center_m=CENTER, seed=0)
    with start_twin_on_free_loopback(60, 79, scene=scene, start_pose=PAD) as twin:
        twin.set_ft_sign(ft_sign)

        def operator_reads_and_pushes(message: object = None, *args: object, **kwargs: object) -> None:
            echo(message, *args, **kwargs)  # type: ignore[arg-type]
            if "push the pad face" in str(message):
                twin.set_placement_error(0.0, -0.0085)

        monkeypatch.setattr(typer, "echo", operator_reads_and_pushes)
        code = cli(["probe", "ur5e", "--host", twin.host, "--sign-check", "--push-timeout", "10"])
    out, err = capfd.readouterr()
    assert "push the pad face back toward the flange" in out
    if ok:
        assert code == 0 and "sign OK" in out
        assert 8.0 < float(out.split(" N along the press direction")[0].split()[-1]) < 16.0
    else:
        assert code == 1 and err.count("\n") == 1
        assert err.startswith("error: wrist-force sign check failed") and "reversed" in err


def test_sign_check_without_a_push_says_so() -> None:
    states = iter(range(10**9))

    def still() -> ArmState:
        return ArmState(
            host_t_ns=next(states) * 2_000_000,
            controller_t_s=0.0,
            tcp_pose=STILL_POSE,
            tcp_force=np.zeros(6),
            robot_mode=7,
            safety_mode=1,
            protective_stop=False,
        )

    with pytest.raises(UsageError, match="no push on the pad within 2 s"):
        run_sign_check(still, echo=lambda _: None, timeout_s=2.0, clock=VirtualClock())


def test_sideways_push_is_not_taken_for_a_good_sign() -> None:
    sideways = np.zeros(6)
    sideways[:3] = 12.0 * np.array([0.0, 0.0, 1.0])  # straight down: across the horizontal press direction
    ok, line = sign_check_verdict(np.zeros(6), sideways, STILL_POSE)
    assert not ok and "sideways" in line

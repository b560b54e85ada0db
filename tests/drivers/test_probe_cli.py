"""``unitac-rig probe`` end to end through the real entry point, on simulated devices (real time, a few frames)."""

from __future__ import annotations

import json

import pytest

from tests.helpers import cli


def run_cli(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = cli(args)
    out, err = capsys.readouterr()
    return code, out, err


def json_lines(out: str) -> list[dict[str, object]]:
    return [json.loads(line) for line in out.splitlines() if line.strip()]


@pytest.mark.parametrize(
    "route",
    [[], ["--can-interface", "slcan"], ["--xela-server", "ws://127.0.0.1:5000"]],
    ids=["virtual-can", "slcan", "xela-server"],
)
def test_probe_uskin_simulated_json(route: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_cli(["probe", "uskin", "--simulated", "--json", "--frames", "3", *route], capsys)
    assert code == 0, err
    records = json_lines(out)
    assert len(records) == 3
    for record in records:
        assert record["sensor"] == "uskin" and record["units"] == "counts"
        values = record["values"]
        assert isinstance(values, list) and len(values) == 24
        assert all(len(row) == 3 and all(isinstance(v, int) and 0 <= v <= 65535 for v in row) for row in values)
        assert isinstance(record["t"], float)
    seqs = [r["seq"] for r in records]
    if route and route[0] == "--xela-server":
        assert all(isinstance(s, int) for s in seqs)
    else:
        assert seqs == [None, None, None]  # raw CAN has no frame counter


def test_probe_papillarray_simulated_json_has_forces_and_displacements(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_cli(["probe", "papillarray", "--simulated", "--json", "--frames", "4", "--slot", "1"], capsys)
    assert code == 0, err
    records = json_lines(out)
    assert len(records) == 4
    seqs = [r["seq"] for r in records]
    assert all(isinstance(s, int) for s in seqs) and seqs == sorted(seqs)
    for record in records:
        assert record["units"] == "N"
        assert isinstance(record["values"], list) and len(record["values"]) == 9
        assert isinstance(record["displacement"], list) and len(record["displacement"]) == 9


def test_probe_without_json_prints_a_taxel_map(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run_cli(["probe", "uskin", "--simulated", "--frames", "2"], capsys)
    assert code == 0
    assert "uSPa46" in out and "col 5" in out and "z " in out


def test_missing_port_is_one_error_line_and_exit_1(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_cli(["probe", "papillarray", "--port", "/dev/ttyACM-not-here", "--timeout", "1"], capsys)
    assert code == 1 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: cannot open PapillArray port") and "dialout" in lines[0]


def test_silent_device_is_a_timeout_error(capsys: pytest.CaptureFixture[str]) -> None:
    # A CAN channel where nothing answers the start command.
    code, _, err = run_cli(
        ["probe", "uskin", "--can-interface", "virtual", "--can-channel", "probe-cli-test-silent", "--timeout", "0.3"],
        capsys,
    )
    assert code == 1
    assert err.startswith("error: uskin: got 0 of 10 frames within 0.3 s") and len(err.strip().splitlines()) == 1


def test_probe_uskin_needs_a_route(capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_cli(["probe", "uskin"], capsys)
    assert code == 2 and "needs --can-interface" in err


def test_probe_of_a_xela_server_that_is_not_there_gives_up_after_its_timeout(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """--timeout bounds finding a networked sensor too, not only its frames (it waited the driver's 5 s before)."""
    import socket

    with socket.socket() as sock:  # a free port, closed again: nothing listens there
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    code, _, err = run_cli(
        ["probe", "uskin", "--xela-server", f"ws://127.0.0.1:{port}", "--timeout", "0.4", "--frames", "2"], capsys
    )
    assert code == 1
    assert f"no xela_server at ws://127.0.0.1:{port} after 0.4 s" in err and len(err.strip().splitlines()) == 1

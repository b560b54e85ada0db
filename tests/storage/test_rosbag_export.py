"""`unitac-rig export --format rosbag2`: each session a ROS 2 bag (MCAP) in standard message types, read back with
rosbags' own reader as `ros2 bag` would: the topics and their types, one wrench and pose per arm sample, one frame
and stamp per tactile frame at the frame's own host time, the values the session holds."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

from tests.helpers import cli
from unitac_rig.storage.reader import list_sessions, read_presses
from unitac_rig.storage.rosbag import quaternions


@pytest.fixture(scope="module")
def pristine(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A simulated-rig session at 3 angles (real streams: a tare, arm poses, device counters)."""
    data = tmp_path_factory.mktemp("rosbag") / "data"
    assert cli(["collect", "--object", "circle_pla", "--data", str(data), "--angles", "3", "--no-live"]) == 0
    return data


@pytest.fixture(scope="module")
def bags(pristine: Path) -> Path:
    out = pristine.parent / "bags"
    assert cli(["export", str(pristine), "--format", "rosbag2", "--out", str(out)]) == 0
    return out


def test_each_session_is_an_mcap_bag_with_every_sample_at_its_own_stamp(bags: Path, pristine: Path) -> None:
    typestore = get_typestore(Stores.ROS2_HUMBLE)
    sessions = list_sessions(pristine)
    assert sorted(p.name for p in bags.iterdir()) == sorted(f"{s.object_id}__{s.sensor}" for s in sessions)
    for info in sessions:
        bag = bags / f"{info.object_id}__{info.sensor}"
        assert (bag / "metadata.yaml").is_file() and len(list(bag.glob("*.mcap"))) == 1
        presses = read_presses(info.path)
        robot_t = np.concatenate([p.robot_t_s for p in presses])
        frame_t = np.concatenate([p.tactile_t_s for p in presses])
        with Reader(bag) as reader:
            types = {c.topic: c.msgtype for c in reader.connections}
            topic = f"/tactile/{info.sensor}"
            assert types == {"/arm/wrench": "geometry_msgs/msg/WrenchStamped",
                             "/arm/tcp_pose": "geometry_msgs/msg/PoseStamped",
                             topic: "std_msgs/msg/Float32MultiArray",
                             f"{topic}/stamp": "sensor_msgs/msg/TimeReference"}  # fmt: skip
            counts = {c.topic: c.msgcount for c in reader.connections}
            assert counts["/arm/wrench"] == counts["/arm/tcp_pose"] == robot_t.size
            assert counts[topic] == counts[f"{topic}/stamp"] == frame_t.size
            got: dict[str, list[tuple[int, object]]] = {}
            for conn, t_ns, raw in reader.messages():
                got.setdefault(conn.topic, []).append((t_ns, typestore.deserialize_cdr(raw, conn.msgtype)))
        frames = got[topic]
        assert [t for t, _ in frames] == sorted(np.round(frame_t * 1e9).astype(np.int64).tolist())
        first = presses[0]
        k = int(np.argmin(first.tactile_t_s))
        assert np.abs(first.tare_baseline).max() > 0  # so the comparison below tells tared from raw
        expected = np.asarray(first.tactile_values[k], np.float32) - np.asarray(first.tare_baseline, np.float32)
        t0 = round(float(first.tactile_t_s[k]) * 1e9)
        message = next(m for t, m in frames if t == t0)
        dims = [(d.label, d.size) for d in message.layout.dim]  # type: ignore[attr-defined]
        assert dims[2] == ("channel_xyz", 3) and dims[0][1] * dims[1][1] == expected.shape[0]
        np.testing.assert_array_equal(np.asarray(message.data).reshape(-1, 3), expected)  # type: ignore[attr-defined]
        stamp = next(m for t, m in got[f"{topic}/stamp"] if t == t0).header.stamp  # type: ignore[attr-defined]
        assert stamp.sec * 1_000_000_000 + stamp.nanosec == t0
        wrench_t, wrench = got["/arm/wrench"][0]
        assert wrench.header.frame_id == "base"  # type: ignore[attr-defined]
        assert wrench_t == round(float(np.min(robot_t)) * 1e9)
        pose_t, pose = got["/arm/tcp_pose"][0]
        earliest = min(presses, key=lambda p: float(np.min(p.robot_t_s)))
        j = int(np.argmin(earliest.robot_t_s))
        position = pose.pose.position  # type: ignore[attr-defined]
        assert pose_t == wrench_t and [position.x, position.y, position.z] == list(earliest.robot_pose[j][:3])
        assert np.abs(earliest.robot_pose[j][:3]).max() > 0


def test_a_rotation_vector_becomes_the_same_rotation_as_a_quaternion() -> None:
    rotvec = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, np.pi / 2], [np.pi, 0.0, 0.0]])
    q = quaternions(rotvec)
    np.testing.assert_allclose(q[0], [0, 0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(q[1], [0, 0, np.sqrt(0.5), np.sqrt(0.5)], atol=1e-12)
    np.testing.assert_allclose(q[2], [1, 0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0)

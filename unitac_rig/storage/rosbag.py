"""``unitac-rig export --format rosbag2``: each recorded session as a ROS 2 bag (MCAP storage, standard ROS 2 Humble
message types) that ``ros2 bag``, Foxglove and the pure-Python ``rosbags`` package (which writes it) open; the
topics, and why the frames are a ``Float32MultiArray``, are in docs/share-your-data.md ("ROS 2 bags"). Times are the
rig host's clock, the one both streams were stamped with.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from unitac_rig.errors import DataError
from unitac_rig.storage.pooling import pooled_export
from unitac_rig.storage.reader import read_presses, read_session_info

log = logging.getLogger(__name__)

FRAME_ID = "base"  # the arm's base frame: wrench and pose are in base axes


@dataclass(frozen=True)
class RosbagExportSummary:
    out: Path
    bags: dict[str, dict[str, int]]  # bag directory name -> messages per topic
    bytes: int


def quaternions(rotvec: np.ndarray) -> np.ndarray:
    """(K, 3) rotation vectors (rad) -> (K, 4) unit quaternions x, y, z, w."""
    angle = np.linalg.norm(rotvec, axis=1)
    half = 0.5 * angle
    # sin(half) / angle, with its limit 1/2 at zero
    scale = np.where(angle > 1e-12, np.sin(half) / np.where(angle > 1e-12, angle, 1.0), 0.5)
    return np.column_stack([rotvec * scale[:, None], np.cos(half)])


def write_session_bag(session: Path, bag: Path, typestore: Any) -> dict[str, int]:
    """Write one session file as the bag directory ``bag`` (must not exist); returns messages per topic."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    sensor = read_session_info(session).sensor
    presses = sorted(read_presses(session), key=lambda r: float(r.tactile_t_s[0]) if len(r.tactile_t_s) else 0.0)
    types = typestore.types
    header_of, vector, stamp_of = (
        types["std_msgs/msg/Header"],
        types["geometry_msgs/msg/Vector3"],
        types["builtin_interfaces/msg/Time"],
    )
    frames_topic = f"/tactile/{sensor}"
    topics = {
        "/arm/wrench": "geometry_msgs/msg/WrenchStamped",
        "/arm/tcp_pose": "geometry_msgs/msg/PoseStamped",
        frames_topic: "std_msgs/msg/Float32MultiArray",
        f"{frames_topic}/stamp": "sensor_msgs/msg/TimeReference",
    }
    layout = _layout(sensor, types)
    counts = dict.fromkeys(topics, 0)

    def time_of(t_ns: int) -> Any:
        return stamp_of(sec=int(t_ns // 1_000_000_000), nanosec=int(t_ns % 1_000_000_000))

    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = {t: writer.add_connection(t, msgtype, typestore=typestore) for t, msgtype in topics.items()}

        def put(topic: str, t_ns: int, **fields: Any) -> None:
            message = types[topics[topic]](**fields)
            writer.write(conn[topic], t_ns, typestore.serialize_cdr(message, topics[topic]))
            counts[topic] += 1

        for rec in presses:
            robot_ns = np.round(np.asarray(rec.robot_t_s, np.float64) * 1e9).astype(np.int64)
            force = np.asarray(rec.robot_force, np.float64).reshape(-1, 6)
            pose = np.asarray(rec.robot_pose, np.float64).reshape(-1, 6)
            quat = quaternions(pose[:, 3:])
            frame_ns = np.round(np.asarray(rec.tactile_t_s, np.float64) * 1e9).astype(np.int64)
            tared = np.asarray(rec.tactile_values, np.float32) - np.asarray(rec.tare_baseline, np.float32)[None]
            # the press's arm samples and frames merged in time order (MCAP needs no order; a player does)
            order = sorted(
                [(int(t), 0, k) for k, t in enumerate(robot_ns)] + [(int(t), 1, k) for k, t in enumerate(frame_ns)]
            )
            for t_ns, kind, k in order:
                if kind == 0:
                    header = header_of(stamp=time_of(t_ns), frame_id=FRAME_ID)
                    f, p, q = force[k], pose[k], quat[k]
                    wrench = types["geometry_msgs/msg/Wrench"](force=vector(*f[:3]), torque=vector(*f[3:]))
                    put("/arm/wrench", t_ns, header=header, wrench=wrench)
                    point, orientation = (
                        types["geometry_msgs/msg/Point"](*p[:3]),
                        types["geometry_msgs/msg/Quaternion"](*q),
                    )
                    put("/arm/tcp_pose", t_ns, header=header, pose=types["geometry_msgs/msg/Pose"](point, orientation))
                    continue
                put(frames_topic, t_ns, layout=layout, data=np.ascontiguousarray(tared[k].reshape(-1)))
                device_us = int(rec.tactile_device_t_us[k])
                source = f"seq={int(rec.tactile_seq[k])}" + ("" if device_us >= 0 else " (no device clock)")
                header = header_of(stamp=time_of(t_ns), frame_id=sensor)
                reference = time_of(device_us * 1000 if device_us >= 0 else t_ns)
                put(f"{frames_topic}/stamp", t_ns, header=header, time_ref=reference, source=source)
    return counts


def _layout(sensor: str, types: Any) -> Any:
    """row x col x channel of the sensor's registered grid (one row of n taxels for a sensor it does not know)."""
    from unitac_rig.rig.sensors import SENSORS

    spec = SENSORS.get(sensor)
    if spec is None:
        raise DataError(f"sensor {sensor!r} is not registered: its taxel grid is unknown")
    rows, cols = spec.layout.rows, spec.layout.cols
    dim, layout = types["std_msgs/msg/MultiArrayDimension"], types["std_msgs/msg/MultiArrayLayout"]
    return layout(
        dim=[
            dim(label="row", size=rows, stride=rows * cols * 3),
            dim(label="col", size=cols, stride=cols * 3),
            dim(label="channel_xyz", size=3, stride=3),
        ],
        data_offset=0,
    )


def export_rosbag2(data_dirs: Sequence[Path], out: Path) -> RosbagExportSummary:
    """Pool ``data_dirs`` and write each session as ``out/<object>__<sensor>/`` (a rosbag2 directory, MCAP storage).
    Built in a hidden sibling directory and renamed into place, so ``out`` is complete or absent."""
    from rosbags.typesys import Stores, get_typestore

    typestore = get_typestore(Stores.ROS2_HUMBLE)
    bags: dict[str, dict[str, int]] = {}
    with pooled_export(data_dirs, out) as (pooled, staging):
        for item in pooled:
            name = f"{item.info.object_id}__{item.info.sensor}"
            bags[name] = write_session_bag(item.info.path, staging / name, typestore)
            log.info("%s: %s", name, bags[name])
    total = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
    return RosbagExportSummary(out, bags, total)

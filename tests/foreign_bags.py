"""A ROS 2 bag gyroemu did not write (rosbags' writer), for the tests of the readers and commands."""

from __future__ import annotations

from pathlib import Path

import numpy as np

N = 60
"""Samples per IMU topic."""


def write_foreign_bag(
    folder: Path,
    imu_topics: tuple[str, ...] = ("/imu_a", "/imu_b"),
    mag_topic: str | None = None,
    n: int = N,
    mag_every: int = 1,
    mag_offset_ns: int = 0,
    compress_each_message: bool = False,
) -> Path:
    """A rosbag2 MCAP bag (rosbags' writer): ``imu_topics`` (/imu_a in a_link, /imu_b in b_link, others in
    imu_link) at 100 Hz with log times 1 ms after their stamps, and a /tf every 5th sample; with
    ``mag_topic``, sensor_msgs/MagneticField on it every ``mag_every``-th sample, ``mag_offset_ns`` from
    its stamp. ``n`` samples; ``compress_each_message``: rosbag2's 'message' compression (zstd), each
    payload a compressed frame. Returns the file."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    t = store.types
    rng = np.random.default_rng(3)
    field_rng = np.random.default_rng(4)
    stamps = 1_700_000_000 * 10**9 + np.arange(n) * 10_000_000
    frames = {"/imu_a": "a_link", "/imu_b": "b_link"}
    writer = Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP)
    if compress_each_message:
        from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

        writer.set_compression(CompressionMode.MESSAGE, CompressionFormat.ZSTD)
    with writer as bag:
        conns = {name: bag.add_connection(name, "sensor_msgs/msg/Imu", typestore=store) for name in imu_topics}
        tf = bag.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=store)
        mag = (
            None
            if mag_topic is None
            else bag.add_connection(mag_topic, "sensor_msgs/msg/MagneticField", typestore=store)
        )
        for k in range(n):
            sec, nanosec = divmod(int(stamps[k]), 10**9)
            stamp = t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)
            for name, frame in ((name, frames.get(name, "imu_link")) for name in imu_topics):
                msg = t["sensor_msgs/msg/Imu"](
                    header=t["std_msgs/msg/Header"](stamp=stamp, frame_id=frame),
                    orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                    orientation_covariance=np.zeros(9),
                    angular_velocity=t["geometry_msgs/msg/Vector3"](*rng.normal(0, 0.01, 3)),
                    angular_velocity_covariance=np.zeros(9),
                    linear_acceleration=t["geometry_msgs/msg/Vector3"](*(rng.normal(0, 0.05, 3) + [0, 0, 9.81])),
                    linear_acceleration_covariance=np.zeros(9),
                )
                bag.write(conns[name], int(stamps[k]) + 1_000_000, store.serialize_cdr(msg, "sensor_msgs/msg/Imu"))
            if mag is not None and k % mag_every == 0:
                sec, nanosec = divmod(int(stamps[k]) + mag_offset_ns, 10**9)
                field = field_rng.normal(0, 1e-7, 3) + [2e-5, 1e-6, -4e-5]
                msg = t["sensor_msgs/msg/MagneticField"](
                    header=t["std_msgs/msg/Header"](
                        stamp=t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec), frame_id="imu_link"
                    ),
                    magnetic_field=t["geometry_msgs/msg/Vector3"](*field),
                    magnetic_field_covariance=np.zeros(9),
                )
                log_ns = int(stamps[k]) + mag_offset_ns + 1_000_000
                bag.write(mag, log_ns, store.serialize_cdr(msg, "sensor_msgs/msg/MagneticField"))
            if k % 5 == 0:
                transform = t["geometry_msgs/msg/TransformStamped"](
                    header=t["std_msgs/msg/Header"](stamp=stamp, frame_id="odom"),
                    child_frame_id="base_link",
                    transform=t["geometry_msgs/msg/Transform"](
                        translation=t["geometry_msgs/msg/Vector3"](x=0.1 * k, y=0.0, z=0.0),
                        rotation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                    ),
                )
                msg = t["tf2_msgs/msg/TFMessage"](transforms=[transform])
                bag.write(tf, int(stamps[k]) + 2_000_000, store.serialize_cdr(msg, "tf2_msgs/msg/TFMessage"))
    return next(folder.glob("*.mcap"))

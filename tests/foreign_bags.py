"""A ROS 2 bag gyroemu did not write (rosbags' writer), for the tests of the readers and commands."""

from __future__ import annotations

from pathlib import Path

import numpy as np

N = 60
"""Samples per IMU topic."""


def write_foreign_bag(folder: Path) -> Path:
    """A rosbag2 MCAP bag (rosbags' writer): /imu_a (a_link) and /imu_b (b_link) at 100 Hz with log times
    1 ms after their stamps, and a /tf every 5th sample. Returns the file."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    t = store.types
    rng = np.random.default_rng(3)
    stamps = 1_700_000_000 * 10**9 + np.arange(N) * 10_000_000
    with Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP) as bag:
        conns = {
            name: bag.add_connection(name, "sensor_msgs/msg/Imu", typestore=store) for name in ("/imu_a", "/imu_b")
        }
        tf = bag.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=store)
        for k in range(N):
            sec, nanosec = divmod(int(stamps[k]), 10**9)
            stamp = t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)
            for name, frame in (("/imu_a", "a_link"), ("/imu_b", "b_link")):
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

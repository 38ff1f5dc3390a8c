"""MCAP files of /imu messages written by the mcap library's own writer (not gyroemu's), with its
options: chunked or not, indexed or not, with a summary or not."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from mcap.writer import Writer

from gyroemu.pipelines.formats.messages import IMU


def write_plain_imu(path: Path, rows: np.ndarray, log_time: Any = None, **options: Any) -> Path:
    """``rows`` (N, size) of encoded Imu messages on /imu, message k logged at ``(k + 1)·10⁷`` ns (or at
    ``log_time``, the same for all), published at 7k, numbered 3k; ``options`` go to the writer."""
    with open(path, "wb") as f:
        writer = Writer(f, **options)
        writer.start("ros2", "test")
        schema = writer.register_schema("sensor_msgs/msg/Imu", "ros2msg", IMU.schema.encode())
        channel = writer.register_channel("/imu", "cdr", schema)
        for k, row in enumerate(rows):
            t = (k + 1) * 10**7 if log_time is None else log_time
            writer.add_message(channel, log_time=t, data=row.tobytes(), publish_time=7 * k, sequence=3 * k)
        writer.finish()
    return path

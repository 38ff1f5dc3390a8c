"""Throughput of gyroemu's MCAP writer and reader, against mcap_ros2's per-message ones in the same run.

    python tests/benchmarks/bench_mcap.py [--samples 500000] [--baseline-samples 50000] [--repeats 3]

A script, not a test (pytest does not collect it). End to end, from arrays to a file and back:

- write: :func:`gyroemu.pipelines.mcap_io.write_mcap` from an ``ImuSamples`` (CDR encoding, Message records,
  zstd chunks, indexes, summary, fsync and rename), and mcap_ros2's ``Writer.write_message`` called
  once per message with the message as a dict built from the same arrays;
- read: :func:`gyroemu.pipelines.mcap_io.read_mcap` to ``ImuSamples``, and the ``mcap`` reader with
  mcap_ros2's ``DecoderFactory`` decoding each message to an object whose fields are copied into
  arrays.

Two gyroemu cases: ``/imu`` alone (the target's "IMU messages"), and a full log of ``/imu``, ``/mag``,
``/truth/imu`` and ``/raw/rlg`` (four messages per sample). The samples are noise around a level
sensor at 1 kHz (noise compresses poorly: the worst case for zstd). Each figure is the best of
``--repeats`` runs after one warm-up. The target: 200 k IMU messages per second both ways. Exit
status 1 if missed.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from mcap.reader import make_reader  # noqa: E402
from mcap_ros2.decoder import DecoderFactory  # noqa: E402
from mcap_ros2.writer import Writer as Ros2Writer  # noqa: E402
from timing import best_time  # noqa: E402

from gyroemu.pipelines.formats.messages import schema_text  # noqa: E402
from gyroemu.pipelines.mcap_io import ImuSeries, Recording, read_mcap, write_mcap  # noqa: E402
from gyroemu.sensors.samples import ImuSamples  # noqa: E402

TARGET = 200e3


def make_samples(n: int, rng: np.random.Generator, full: bool):
    t = np.arange(1, n + 1) * 1e-3
    gyro = rng.normal(0.0, 1e-3, (n, 3))
    accel = np.array([0.0, 0.0, 9.81]) + rng.normal(0.0, 1e-2, (n, 3))
    mag = np.array([2e-5, 0.0, -4e-5]) + rng.normal(0.0, 1e-7, (n, 3)) if full else np.full((n, 3), np.nan)
    raw = {}
    truth = None
    if full:
        raw = {
            "rlg": {
                "fringe_count": np.cumsum(rng.integers(0, 3, (n, 3)), axis=0),
                "beat_phase_rad": rng.normal(size=(n, 3)),
                "dither_angle_rad": rng.normal(0, 1e-3, (n, 3)),
            }
        }
        q = np.column_stack([np.ones(n), rng.normal(0, 1e-3, (n, 3))])
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        truth = ImuSeries(t=t, q_wb=q, omega_b=gyro + rng.normal(0, 1e-4, (n, 3)), specific_force_b=accel)
    return Recording(ImuSamples(t=t, gyro=gyro, accel=accel, mag=mag, raw=raw, device="imu0"), truth=truth)


def baseline_write(path: Path, samples: ImuSamples) -> None:
    """mcap_ros2: one dict and one write_message call per message."""
    with open(path, "wb") as f:
        writer = Ros2Writer(f)
        schema = writer.register_msgdef("sensor_msgs/msg/Imu", schema_text("sensor_msgs/msg/Imu"))
        stamps = np.rint(samples.t * 1e9).astype(np.int64)
        no_orientation = [-1.0] + [0.0] * 8
        zeros = [0.0] * 9
        for k, (stamp, g, a) in enumerate(zip(stamps.tolist(), samples.gyro.tolist(), samples.accel.tolist())):
            sec, nanosec = divmod(stamp, 1_000_000_000)
            writer.write_message(
                "/imu",
                schema,
                {
                    "header": {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": samples.device},
                    "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
                    "orientation_covariance": no_orientation,
                    "angular_velocity": {"x": g[0], "y": g[1], "z": g[2]},
                    "angular_velocity_covariance": zeros,
                    "linear_acceleration": {"x": a[0], "y": a[1], "z": a[2]},
                    "linear_acceleration_covariance": zeros,
                },
                log_time=stamp,
                publish_time=stamp,
                sequence=k,
            )
        writer.finish()


def baseline_read(path: Path):
    """mcap reader + mcap_ros2 decoder: one decoded object per message, fields copied into arrays."""
    t, gyro, accel = [], [], []
    with open(path, "rb") as f:
        for _, _, _, msg in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(topics=["/imu"]):
            t.append(msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9)
            w, a = msg.angular_velocity, msg.linear_acceleration
            gyro.append((w.x, w.y, w.z))
            accel.append((a.x, a.y, a.z))
    return np.array(t), np.array(gyro), np.array(accel)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=500_000, help="samples per gyroemu run")
    parser.add_argument("--baseline-samples", type=int, default=50_000, help="samples per mcap_ros2 run")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    n, m = args.samples, args.baseline_samples
    imu_only = make_samples(n, rng, full=False)
    full = make_samples(n, rng, full=True)
    baseline = make_samples(m, rng, full=False)

    with tempfile.TemporaryDirectory(prefix="bench_mcap_") as folder:
        folder = Path(folder)
        rows = []  # (case, messages, IMU messages, seconds, file)

        def case(name, run, messages, imu_messages, file):
            seconds = best_time(run, args.repeats)
            rows.append((name, messages, imu_messages, seconds, file))

        case("gyroemu write  /imu", lambda: write_mcap(folder / "imu.mcap", imu_only), n, n, folder / "imu.mcap")
        case("gyroemu read   /imu", lambda: read_mcap(folder / "imu.mcap"), n, n, folder / "imu.mcap")
        case(
            "gyroemu write  /imu /mag /truth/imu /raw/rlg",
            lambda: write_mcap(folder / "full.mcap", full),
            4 * n,
            n,
            folder / "full.mcap",
        )
        case(
            "gyroemu read   /imu /mag /truth/imu /raw/rlg",
            lambda: read_mcap(folder / "full.mcap"),
            4 * n,
            n,
            folder / "full.mcap",
        )
        case(
            "mcap_ros2 write /imu (baseline)",
            lambda: baseline_write(folder / "base.mcap", baseline.samples),
            m,
            m,
            folder / "base.mcap",
        )
        case("mcap_ros2 read  /imu (baseline)", lambda: baseline_read(folder / "base.mcap"), m, m, folder / "base.mcap")

        # the two writers produce the same messages: check on the baseline's content
        ours = read_mcap(write_mcap(folder / "check.mcap", baseline.samples)).samples
        t, gyro, accel = baseline_read(folder / "base.mcap")
        assert np.array_equal(ours.gyro, gyro) and np.array_equal(ours.accel, accel)

        print(f"gyroemu {n:,} samples, mcap_ros2 {m:,} samples at 1 kHz; best of {args.repeats}; {os.cpu_count()} CPUs")
        print(f"{'case':46s} {'s':>7s} {'k msg/s':>9s} {'k IMU msg/s':>12s} {'MB':>7s}")
        for name, messages, imu_messages, seconds, file in rows:
            print(
                f"{name:46s} {seconds:7.3f} {messages / seconds / 1e3:9.0f} {imu_messages / seconds / 1e3:12.0f} "
                f"{file.stat().st_size / 1e6:7.1f}"
            )

    rate = {name: imu / seconds for name, _, imu, seconds, _ in rows}
    write, read = rate["gyroemu write  /imu"], rate["gyroemu read   /imu"]
    base_write, base_read = rate["mcap_ros2 write /imu (baseline)"], rate["mcap_ros2 read  /imu (baseline)"]
    print(
        f"\ntarget {TARGET / 1e3:.0f} k IMU messages/s:  write {write / 1e3:.0f} k/s "
        f"{'met' if write >= TARGET else 'MISSED'} ({write / base_write:.0f}x mcap_ros2),  read {read / 1e3:.0f} k/s "
        f"{'met' if read >= TARGET else 'MISSED'} ({read / base_read:.0f}x mcap_ros2)"
    )
    return 0 if write >= TARGET and read >= TARGET else 1


if __name__ == "__main__":
    sys.exit(main())

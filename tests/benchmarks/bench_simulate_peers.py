"""Throughput of ``gyroemu simulate`` and of the Python API against peers, for the same sample count.

    python tests/benchmarks/bench_simulate_peers.py [--samples 600000] [--repeats 3] [--rates 100 1000]

A script, not a test (pytest does not collect it). For each output rate (100 Hz: 6,000 s, 1 kHz: 600 s
for the default 600 k samples) the motion is ``smooth_manoeuvre``, simulated by
``load_scenario("smooth_manoeuvre").simulate(duration=..., rate_hz=rate)``, and the device is
``consumer_mems``. Rows, timed in the same run (median of ``--repeats``, after one warm-up that loads
the numba kernels):

- ``numpy``: ``rng.standard_normal((n, 9))``, the draw of n white 9-axis samples (a floor, no physics);
- ``ahrs.Sensors``: the ``ahrs`` library's synthetic IMU built from the same truth's quaternions
  (``ahrs.Sensors(quaternions=q_wb, freq=rate)``); only its construction (which generates the data) is
  timed, the truth is made beforehand;
- ``gyroemu API``: ``device.measure(truth)``, the truth's simulation *included* in the timing;
- ``gyroemu simulate``: ``gyroemu simulate --scenario smooth_manoeuvre --device <toml> --duration D
  --rate R --out x.mcap`` end to end as a subprocess (process start, truth, device, MCAP written).

``consumer_mems`` at 100 Hz is refused by the quantiser check (``DITHER_MIN_SIGMA_LSB``: its 2.8
mdps/√Hz white noise is 0.357 LSB of the 16-bit ±2000 °/s quantiser at 100 Hz, below the 0.5 LSB that
dithers it), so at 100 Hz the benchmark uses the part's ±1000 °/s full scale (``range_deg_per_s =
1000``, ``quantisation_rad_per_s = 5.3265e-4``, 16 bits: 0.71 LSB), everything else as the preset. Its
device TOML is written to a temporary folder and passed to the CLI with ``--device``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

import numpy as np
from timing import median_wall_cpu  # (tests/benchmarks is the script folder)

from gyroemu.dynamics import load_scenario
from gyroemu.sensors import Device, device_from_dict

PRESET = Path(__file__).resolve().parents[2] / "configs" / "devices" / "consumer_mems.toml"

MODELS = {
    "numpy": "models: nothing (white Gaussian draws); leaves out: every sensor, the motion, every error term",
    "ahrs.Sensors": "models: gyro from quaternion finite differences, gravity and a fixed field rotated into "
    "the body, white noise, a constant uniform gyro bias; leaves out: linear acceleration, bias drift, "
    "random walks, scale factor, misalignment, quantisation, range, filters, the mechanism, MCAP output",
    "gyroemu API": "models: the MEMS proof-mass mechanism stepped exactly per output interval (Coriolis, quadrature, "
    "g-sensitivity, Brownian noise, demodulator filter), every IEEE error term (white noise, bias "
    "instability, rate random walk, turn-on bias, scale factor, misalignment, range, quantisation), "
    "accelerometer with linear acceleration, magnetometer; leaves out: nothing of the device file",
    "gyroemu simulate": "models: as the API, plus process start, truth channels (/truth/imu, /truth/pose) "
    "and the ROS 2 MCAP file written",
}


def device_dict(rate_hz: float) -> dict:
    """``consumer_mems`` at ``rate_hz``; at 100 Hz with the ±1000 °/s scale (see the module notes)."""
    data = tomllib.loads(PRESET.read_text())
    data["rate_hz"] = rate_hz
    if rate_hz < 1000:
        data["gyro"]["errors"]["range_deg_per_s"] = 1000.0
        data["gyro"]["errors"]["quantisation_rad_per_s"] = 5.3265e-4
    return data


def toml_text(data: dict) -> str:
    """A device dict as TOML (flat tables of scalars and lists)."""
    import tomli_w

    return tomli_w.dumps(data)


def bench_rate(rate: float, samples: int, repeats: int, folder: Path) -> dict[str, tuple[float, float]]:
    """Wall and CPU seconds per row for ``samples`` samples at ``rate``."""
    import ahrs

    duration = samples / rate
    scenario = load_scenario("smooth_manoeuvre")
    data = device_dict(rate)
    device: Device = device_from_dict(data, name="consumer_mems", seed=0)
    toml = folder / f"consumer_mems_{rate:g}hz.toml"
    toml.write_text(toml_text(data))
    truth = scenario.simulate(duration=duration, rate_hz=rate)
    rng = np.random.default_rng(0)
    out = folder / "x.mcap"
    command = [
        sys.executable,
        "-m",
        "gyroemu",
        "simulate",
        "--scenario",
        "smooth_manoeuvre",
        "--device",
        str(toml),
        "--duration",
        f"{duration:g}",
        "--rate",
        f"{rate:g}",
        "--out",
        str(out),
        "--force",  # each repeat writes the same file again
    ]

    def api() -> None:
        device.measure(scenario.simulate(duration=duration, rate_hz=rate))

    def cli() -> None:
        subprocess.run(command, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    return {
        "numpy": median_wall_cpu(lambda: rng.standard_normal((samples, 9)), repeats),
        "ahrs.Sensors": median_wall_cpu(lambda: ahrs.Sensors(quaternions=truth.q_wb, freq=rate, rng=rng), repeats),
        "gyroemu API": median_wall_cpu(api, repeats),
        "gyroemu simulate": median_wall_cpu(cli, repeats),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=600_000, help="samples per run (default 600000)")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per row, median (default 3)")
    parser.add_argument("--rates", type=float, nargs="+", default=[100.0, 1000.0], help="output rates, Hz")
    args = parser.parse_args()
    os.environ.setdefault("PYTHONWARNINGS", "ignore")
    print(f"{args.samples} samples of consumer_mems on smooth_manoeuvre, median of {args.repeats}")
    print(
        f"{'rate':>7s}  {'row':18s} {'seconds':>8s} {'M samples/s':>12s} {'vs ahrs':>8s} {'vs numpy':>9s} {'cpu s':>7s}"
    )
    with tempfile.TemporaryDirectory() as folder:
        for rate in args.rates:
            seconds = bench_rate(rate, args.samples, args.repeats, Path(folder))
            ahrs_s, numpy_s = seconds["ahrs.Sensors"][0], seconds["numpy"][0]
            for row, (s, cpu) in seconds.items():
                print(
                    f"{rate:5g}Hz  {row:18s} {s:8.3f} {args.samples / s / 1e6:12.3f} "
                    f"{ahrs_s / s:7.2f}x {numpy_s / s:8.3f}x {cpu:7.2f}"
                )
    print("gyroemu API: the truth's simulation is inside the timing; ahrs.Sensors: only its construction.")
    for row, text in MODELS.items():
        print(f"{row}: {text}")


if __name__ == "__main__":
    main()

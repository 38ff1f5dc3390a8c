"""Every built-in device loads, measures, and is reproducible; presets list and Allan commands work."""

import subprocess
import sys

import numpy as np
import pytest

from gyroemu.dynamics import load_scenario
from gyroemu.dynamics.config import config_dir
from gyroemu.sensors import ConfigError, load_device

PRESETS = sorted(p.stem for p in (config_dir() / "devices").glob("*.toml"))


@pytest.fixture(scope="module")
def manoeuvre():
    return load_scenario("smooth_manoeuvre").simulate(duration=2.0)


@pytest.mark.parametrize("name", PRESETS)
def test_preset_measures_reproducibly(name, manoeuvre):
    a = load_device(name, seed=5).measure(manoeuvre)
    b = load_device(name, seed=5).measure(manoeuvre)
    assert len(a) == int(2.0 * load_device(name).spec.rate_hz)
    assert np.all(np.isfinite(a.gyro)) and np.all(np.isfinite(a.accel))
    assert a.gyro.tobytes() == b.gyro.tobytes() and a.accel.tobytes() == b.accel.tobytes()
    # Within the error budget of the true mean rate: a sanity bound of 0.1 rad/s for every grade.
    truth = np.column_stack([np.interp(a.t_true, manoeuvre.t, manoeuvre.omega_b[:, i]) for i in range(3)])
    assert np.abs(np.median(a.gyro - truth, axis=0)).max() < 0.1


def test_unknown_preset_is_named():
    with pytest.raises(ConfigError, match="unknown device 'navigation_fgo'.*did you mean 'navigation_fog'"):
        load_device("navigation_fgo")


def gyroemu(*args):
    return subprocess.run([sys.executable, "-m", "gyroemu", *args], capture_output=True, text=True)


def test_presets_command_lists_every_preset():
    result = gyroemu("presets")
    assert result.returncode == 0, result.stderr
    assert {line.split()[0] for line in result.stdout.splitlines()[1:]} == set(PRESETS)


def test_allan_command_fits_a_log_and_draws_the_plot(tmp_path):
    log = tmp_path / "static.npz"
    device = tmp_path / "dev.toml"
    device.write_text('description = "x"\nrate_hz = 50\n[gyro.errors]\narw_deg_per_sqrt_h = 2.0\n')
    result = gyroemu(
        "simulate", "--scenario", "bench_static", "--device", str(device), "--duration", "600", "--out", str(log)
    )
    assert result.returncode == 0, result.stderr
    result = gyroemu("allan", str(log), "--out", str(tmp_path / "allan.png"))
    assert result.returncode == 0, result.stderr
    arw = [float(v) for v in next(line for line in result.stdout.splitlines() if line.startswith("arw")).split()[2:6]]
    # 30 000 samples: the ARW read off the curve is within a few percent of 2 deg/sqrt(h); allow 15 %.
    assert all(abs(v / 2.0 - 1) < 0.15 for v in arw[:3]) and arw[3] == pytest.approx(2.0)
    assert (tmp_path / "allan.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    bad = gyroemu("allan", str(device))
    assert bad.returncode == 2 and str(device) in bad.stderr

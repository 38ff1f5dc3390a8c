"""The ``/imu`` angular-velocity covariance against a counting gyro's static output.

A ring laser's output is its fringe count: each sample's rate is the difference of two counts over
``T``, each off by a uniform error of one fringe ``q``, so the counts add ``2 (q/T)²/12`` to the
sample variance (``gyroemu.pipelines.formats.imu_covariance``, module notes). For ``navigation_rlg``
(q = 2.26″ at 1 kHz) that is 4.5·10⁻³ rad/s, ~140× its white noise.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import chi2

from gyroemu.dynamics.scenarios import load_scenario
from gyroemu.pipelines.formats.imu_covariance import measurement_variances
from gyroemu.sensors import load_device
from gyroemu.sensors.presets import list_devices


def test_rlg_covariance_holds_the_fringe_quantisation():
    device = load_device("navigation_rlg", seed=2)
    trajectory = load_scenario("bench_static").simulate(duration=10.0, rate_hz=100)
    gyro = device.measure_held_still(trajectory).gyro
    n = len(gyro)
    assert n == 10_000
    covariance = measurement_variances(device)[0]
    s2 = gyro.var(axis=0, ddof=1)
    # The two counts' errors make the samples an MA(1) process (lag-1 correlation −1/2): the sample
    # variance of a Gaussian process then has variance (2σ⁴/n) Σ_k ρ_k² = 1.5 × the white one
    # (Priestley, Spectral Analysis and Time Series, 1981, §5.3.3), so the chi-squared bounds use
    # n/1.5 degrees of freedom (the triangular count error's negative excess kurtosis only narrows them).
    dof = (n - 1) / 1.5
    alpha = 1e-6
    low, high = chi2.ppf(alpha / 2, dof) / dof, chi2.ppf(1 - alpha / 2, dof) / dof
    ratio = s2 / covariance
    assert np.all((low <= ratio) & (ratio <= high)), (ratio, low, high)


def test_only_counting_mechanisms_report_a_counter_quantum():
    quanta = {d.kind: d.mechanism.output_angle_quantum() for d in list_devices()}
    assert quanta.pop("rlg") == load_device("navigation_rlg").mechanism.fringe_angle_rad
    assert set(quanta.values()) == {None}

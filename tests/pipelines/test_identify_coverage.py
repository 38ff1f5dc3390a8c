"""The white-noise interval of ``gyroemu identify`` holds the device's N as often as a 68 % interval should.

``consumer_mems`` lying still 30 s (``tests/noise_coverage.py``: each run its own device seed, the rest
phases found as ``identify`` finds them), the gyro's and the accelerometer's three axes: 20 runs give
n = 120 independent intervals. An exact 68 % interval holds its truth in a binomial number of them, of
mean 0.683 n and standard deviation √(0.683·0.317 n); the test asks for at least 0.683 n less three
of those (67 of 120), a bound an honest or cautious interval misses with probability 0.0013.

With the interval read off one τ (before the fit's covariance was counted) and the τ⁻² term held
non-negative (before the band limit), 35 of 120 held: the gyro's N came out 1.2–1.6 % low (the MEMS
demodulator's low-pass takes Allan variance off the short octaves, sensors/allan.py module notes) with
a half-width of 0.4–0.5 %, and the accelerometer's intervals, blind to N's trade with the quantisation
term, held 25 of 60.
"""

from __future__ import annotations

from noise_coverage import binomial_band, rest_draws

SEEDS = 20
REST_S = 30.0


def test_white_noise_interval_holds_the_devices_density_as_often_as_it_says():
    runs = held = 0
    missed = []
    for sensor, axis, truth, term in rest_draws("consumer_mems", REST_S, SEEDS):
        runs += 1
        if term.low <= truth <= term.high:
            held += 1
        else:
            missed.append(f"{sensor} {axis} {truth:.5g} not in [{term.low:.5g}, {term.high:.5g}]")
    low, _ = binomial_band(runs)
    assert runs == 6 * SEEDS
    assert held >= low * runs, f"{held} of {runs} held (at least {low * runs:.1f}): " + "; ".join(missed)

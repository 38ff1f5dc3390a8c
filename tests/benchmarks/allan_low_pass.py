"""White noise behind a low-pass, fitted over every octave and from where the low-pass has forgotten its
input (:func:`gyroemu.sensors.allan.fit_band_limited`): how far the white-noise density N reads off.

    python tests/benchmarks/allan_low_pass.py [--runs 20] [--seconds 300] [--rate-hz 100]

A script, not a test (``tests/sensors/test_allan_low_pass_reach.py`` holds the figures on 8 runs). Each
run draws white noise of density N at the rate, passes it through the filter (a first-order low-pass
y_k = a y_(k−1) + (1 − a) x_k, a = e^(−2π f_c Δt), or a Butterworth of order 2 or 4 from
``scipy.signal.butter``), settled for 50 s first, and fits the overlapping Allan deviation of the rest.
Printed per filter and cut-off: the mean and standard deviation over the runs of N̂/N − 1 for the fit
over every octave (``fit_allan(..., band_limit=True)``) and for ``fit_band_limited``, the octaves the
latter left out, and how many runs its 68 % interval held N in.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
from scipy.signal import butter, lfilter

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from gyroemu.sensors.allan import allan_deviation, fit_allan, fit_band_limited  # noqa: E402

N = 0.01


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--seconds", type=float, default=300.0)
    parser.add_argument("--rate-hz", type=float, default=100.0)
    args = parser.parse_args()
    fs = args.rate_hz
    print(f"{args.runs} runs of {args.seconds:g} s at {fs:g} Hz, N = {N}: N̂/N − 1, mean ± sd over the runs")
    print(f"{'filter':<14}{'cut-off':>10}{'every octave':>22}{'from the reach':>22}{'left out':>10}{'held':>8}")
    for order in (None, 1, 2, 4):
        for divisor in (4, 10, 40) if order is not None else (None,):
            plain, reached, skipped, held = [], [], set(), 0
            for seed in range(args.runs):
                x = np.random.default_rng(seed).standard_normal(int((args.seconds + 50) * fs)) * N * math.sqrt(fs)
                if order == 1:
                    a = math.exp(-2 * math.pi / divisor)
                    x = lfilter([1 - a], [1, -a], x)
                elif order is not None:
                    b, a_coef = butter(order, 2.0 / divisor)  # cut-off fs/divisor, as a fraction of Nyquist
                    x = lfilter(b, a_coef, x)
                allan = allan_deviation(x[int(50 * fs) :], 1 / fs)
                plain.append(fit_allan(allan, band_limit=True).arw.value / N - 1)
                fit = fit_band_limited(allan)
                reached.append(fit.arw.value / N - 1)
                skipped.add(fit.skipped)
                held += fit.arw.low <= N <= fit.arw.high
            name = "none" if order is None else "first order" if order == 1 else f"Butterworth {order}"
            cut = "-" if divisor is None else f"fs/{divisor}"
            print(
                f"{name:<14}{cut:>10}{np.mean(plain) * 100:>+12.2f} ± {np.std(plain) * 100:5.2f} %"
                f"{np.mean(reached) * 100:>+12.2f} ± {np.std(reached) * 100:5.2f} %"
                f"{','.join(map(str, sorted(skipped))):>10}{held:>5}/{args.runs}",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())

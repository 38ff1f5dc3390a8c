"""A filter's state carries over from block to block (``protocol.py``): after the first block, from which
a filter initialises, how a log is cut into blocks changes nothing, to the bit. ``gyroemu estimate``
feeds a log a block at a time, a live stream feeds what has arrived; both must give the bytes a whole
run gives."""

from dataclasses import replace

import numpy as np
import pytest

from gyroemu.dynamics import load_scenario
from gyroemu.pipelines.estimation import setup_for
from gyroemu.pipelines.estimation.protocol import Estimate
from gyroemu.pipelines.estimation.registry import FILTERS, is_offline, make_filter, unavailable_filters
from gyroemu.sensors import load_device

ONLINE = sorted(name for name in FILTERS if not is_offline(name) and name not in unavailable_filters())
FIRST_BLOCK_S = 12.0  # beyond what any built-in reads to initialise (the MEKF's gyrocompass: 10 s)


@pytest.fixture(scope="module")
def run():
    scenario = load_scenario("smooth_manoeuvre")
    device = load_device("consumer_mems", seed=3)
    samples = device.measure(scenario.simulate(duration=30.0))
    return setup_for(device, scenario), samples


def cuts(n: int, first: int, rng: np.random.Generator) -> list[int]:
    """Block ends: the first block, then blocks of 1 to 400 samples (some a single sample)."""
    ends = [first]
    while ends[-1] < n:
        ends.append(min(n, ends[-1] + int(rng.choice([1, rng.integers(2, 40), rng.integers(40, 400)]))))
    return [0, *ends]


@pytest.mark.parametrize("name", ONLINE)
@pytest.mark.parametrize("nine", [True, False], ids=["9D", "6D"])
@pytest.mark.parametrize("latency", [False, True], ids=["untimed", "timed"])
def test_blocks_give_the_whole_runs_bytes(run, name, nine, latency):
    setup, s = run
    setup = replace(setup, use_mag=nine)
    if latency:  # LatencyCompensated around the filter: its rules must not depend on the cut either
        setup = replace(setup, gyro_latency_s=0.003, mag_latency_s=0.012)
    mag = s.mag if nine else None
    whole = make_filter(name, setup).process(s.t, s.gyro, s.accel, mag)
    ends = cuts(len(s.t), int(np.searchsorted(s.t, s.t[0] + FIRST_BLOCK_S)), np.random.default_rng(7))
    assert len(ends) > 40  # many cuts, mid-window and single samples among them
    flt = make_filter(name, setup)
    parts = [
        flt.process(s.t[i:j], s.gyro[i:j], s.accel[i:j], None if mag is None else mag[i:j])
        for i, j in zip(ends[:-1], ends[1:])
    ]
    blocks = Estimate.concatenate(parts)
    for field in ("q_wb", "gyro_bias", "q_wb_covariance"):
        a, b = getattr(whole, field), getattr(blocks, field)
        assert (a is None) == (b is None), field
        if a is not None:
            assert a.tobytes() == b.tobytes(), field

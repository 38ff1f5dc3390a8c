"""``gyroemu estimate --plot`` and ``gyroemu info --plot`` (pipelines/jobs/plots.py).

The angles are checked on rotations built from known angles (exact to a few ε of the angle); the
pictures by what the CLI writes: a PNG (its signature) of the size matplotlib gives the figure.
"""

from __future__ import annotations

import struct

import numpy as np
import pytest

from gyroemu.pipelines.jobs.plots import attitude_error_deg, euler_zyx_deg


def _q(axis, angle):
    axis = np.asarray(axis, dtype=float)
    return np.array([np.cos(angle / 2), *(np.sin(angle / 2) * axis / np.linalg.norm(axis))])


def _mul(a, b):
    w1, v1, w2, v2 = a[0], a[1:], b[0], b[1:]
    return np.array([w1 * w2 - v1 @ v2, *(w1 * v2 + w2 * v1 + np.cross(v1, v2))])


def test_euler_angles_and_error_of_known_rotations():
    rng = np.random.default_rng(1)
    angles = np.column_stack([rng.uniform(-170, 170, 50), rng.uniform(-80, 80, 50), rng.uniform(-170, 170, 50)])
    q = np.array(
        [
            _mul(_mul(_q([0, 0, 1], np.radians(y)), _q([0, 1, 0], np.radians(p))), _q([1, 0, 0], np.radians(r)))
            for r, p, y in angles
        ]
    )
    assert np.allclose(euler_zyx_deg(q), angles, rtol=0, atol=1e-10)
    assert np.all(np.isnan(euler_zyx_deg(np.full((1, 4), np.nan))))
    small = np.array([_mul(qk, _q([1, 2, 3], 1e-9)) for qk in q])  # 1e-9 rad about a body axis
    assert np.allclose(attitude_error_deg(q, small), np.degrees(1e-9), rtol=1e-6, atol=0)
    assert np.allclose(attitude_error_deg(q, -q), 0.0, atol=1e-12)  # q and -q: the same attitude


def _png_size(path):
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", data[16:24])


@pytest.mark.slow  # matplotlib's import and two figures: 2.4 s, over the fast tier's share
@pytest.mark.filterwarnings("ignore")
def test_estimate_and_info_draw_their_pictures(tmp_path, capsys):
    from gyroemu.pipelines.cli import main

    log, out = tmp_path / "run.mcap", tmp_path / "est.mcap"
    common = ["--device", "tactical_mems", "--duration", "2", "--seed", "3"]
    assert main(["simulate", "--scenario", "smooth_manoeuvre", *common, "--out", str(log)]) == 0
    assert main(["estimate", str(log), "--out", str(out), "--plot"]) == 0
    assert "drew" in capsys.readouterr().out
    assert _png_size(tmp_path / "est.estimate.png") == (770, 1320)  # 7 x 12 in at 110 dpi
    assert main(["info", str(log), "--plot"]) == 0
    assert _png_size(tmp_path / "run.info.png") == (770, 990)  # 7 x 9 in

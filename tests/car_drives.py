"""Car drives drawn per run, so that runs of the car scenario are independent draws (the NEES check's
χ² band needs them: ``tests/pipelines/test_mekf_nees.py``, ``tests/benchmarks/nees_check.py``)."""

import numpy as np


def drawn_car_drive(data: dict, seed: int, heading: bool = True) -> dict:
    """The car drive ``data`` (its TOML table) with its first part drawn from ``seed``: the first two
    legs (hold 2–4 s at rest, then 10–16 m/s), acceleration 2–3 m/s² and braking 3–5 m/s², the first
    turn (150–300 m from the start, 150–250 m long, left or right by up to the angle that keeps its
    peak lateral acceleration, (16/5) angle v² / length, within the scenario's 4.9 m/s²), the first
    bump (at 8–28 s, 1–3 cm, 0.3–1°), and with ``heading`` the initial heading (0–360°)."""
    rng = np.random.default_rng(seed)
    drive = dict(data["drive"], accel_m_s2=float(rng.uniform(2.0, 3.0)), brake_m_s2=float(rng.uniform(3.0, 5.0)))
    yaw = float(rng.uniform(0.0, 360.0))
    if heading:
        drive["initial_yaw_deg"] = yaw
    speed = float(rng.uniform(10.0, 16.0))
    legs = [dict(speed_m_s=0.0, hold_s=float(rng.uniform(2.0, 4.0))), dict(data["legs"][1], speed_m_s=speed)]
    length = float(rng.uniform(150.0, 250.0))
    angle_max = min(90.0, float(np.degrees(4.9 * length / (3.2 * speed * speed))))
    turn = dict(
        start_m=float(rng.uniform(150.0, 300.0)),
        length_m=length,
        angle_deg=float(rng.choice([-1.0, 1.0]) * rng.uniform(0.5, 1.0) * angle_max),
    )
    bump = dict(
        at_s=float(rng.uniform(8.0, 28.0)),
        heave_m=float(rng.uniform(0.01, 0.03)),
        nose_up_deg=float(rng.uniform(0.3, 1.0)),
    )
    return data | {
        "drive": drive,
        "legs": legs + data["legs"][2:],
        "turns": [turn] + data["turns"][1:],
        "bumps": [bump] + data["bumps"][1:],
    }

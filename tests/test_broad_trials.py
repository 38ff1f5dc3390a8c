"""The BROAD data helper: a missing dataset skips and says where it looked, or fails when required."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent

PROBE = """
from broad_trials import needs_trial

@needs_trial("02_undisturbed_slow_rotation_B.hdf5")
def test_probe():
    pass
"""


@pytest.mark.parametrize("required, outcome", [("", "1 skipped"), ("1", "1 failed")])
def test_missing_data_skips_or_fails_when_required(tmp_path, required, outcome):
    (tmp_path / "test_probe.py").write_text(PROBE)
    env = {**os.environ, "GYROEMU_BROAD_DIR": str(tmp_path / "nowhere"), "GYROEMU_REQUIRE_DATA": required}
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            "-p",
            "no:cacheprovider",
            "-n",
            "0",
            "-rs",
            "-o",
            "addopts=",
            f"--rootdir={tmp_path}",
            "--import-mode=importlib",
            str(tmp_path / "test_probe.py"),
        ],
        capture_output=True,
        text=True,
        env={**env, "PYTHONPATH": str(TESTS)},
        cwd=tmp_path,
        check=False,
    )
    assert outcome in done.stdout, done.stdout
    assert str(tmp_path / "nowhere") in done.stdout  # says where it looked

"""``gyroemu simulate`` never writes over a file it reads, whatever that file's name."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from cli_runs import run_cli

from gyroemu.dynamics.config import config_dir
from gyroemu.pipelines.jobs.simulate import SimulateError, SimulateOptions, check_options


@pytest.mark.parametrize("given", ["scenario", "device"])
@pytest.mark.parametrize("suffix", [".mcap", ".npz"])
def test_simulate_force_refuses_a_config_file_of_the_outputs_suffix(tmp_path, monkeypatch, given, suffix):
    """The config resolver reads any path it is given as TOML, so a scenario or device file named
    ``*.mcap`` / ``*.npz`` is an input: ``--out`` naming it is refused with --force too (exit 2, before any
    work), and the file keeps its bytes; by a bare name in the working folder as by a path."""
    monkeypatch.chdir(tmp_path)
    source = config_dir() / ("scenarios/heavy_top.toml" if given == "scenario" else "devices/consumer_mems.toml")
    config = Path(f"cfg{suffix}")
    shutil.copyfile(source, config)
    before = config.read_bytes()
    scenario, device = (str(config), "consumer_mems") if given == "scenario" else ("heavy_top", str(config))
    for out in (config, tmp_path / config):
        options = SimulateOptions(scenario=scenario, device=device, out=out, duration=0.2, force=True)
        with pytest.raises(SimulateError, match="is an input"):
            check_options(options)
    argv = ["simulate", "--scenario", scenario, "--device", device, "--duration", "0.2", "--out", str(config)]
    code, stdout, stderr = run_cli([*argv, "--force"])
    assert code == 2 and stdout == "", stderr
    assert f"argument --out: {config} is an input" in stderr and "never overwritten" in stderr, stderr
    assert config.read_bytes() == before

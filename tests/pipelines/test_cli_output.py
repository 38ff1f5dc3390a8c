"""Machine-readable output (``--json``), ``info``'s per-topic figures, one-line warnings with ``-q``/``-v``,
and the shell completion scripts."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import warnings

import numpy as np
import pytest

from gyroemu.pipelines.cli import build_parser, main
from gyroemu.pipelines.completion import subcommands
from gyroemu.pipelines.formats.mcap_log import LogWarning, McapLogWriter
from gyroemu.pipelines.jobs.info import topic_stats
from gyroemu.pipelines.jobs.simulate import SimulateOptions, run_simulate
from gyroemu.pipelines.log_setup import cli_logging
from gyroemu.sensors.samples import ImuSamples

SUBCOMMANDS = subcommands(build_parser())


def gyroemu(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "gyroemu", *args], capture_output=True, text=True)


def run_json(capsys, *args: str):
    assert main([*args, "--json"]) == 0
    out = capsys.readouterr().out
    return json.loads(out)


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    """5 s of bench_static by consumer_mems (1000 Hz)."""
    out = tmp_path_factory.mktemp("log") / "x.mcap"
    run_simulate(SimulateOptions(scenario="bench_static", device="consumer_mems", duration=5, out=out, progress=False))
    return out


def _samples(t: np.ndarray) -> ImuSamples:
    n = len(t)
    accel = np.tile([0.0, 0.0, 9.81], (n, 1))
    return ImuSamples(t=t, gyro=np.zeros((n, 3)), accel=accel, mag=np.full((n, 3), np.nan), device="imu0")


def test_scenarios_and_presets_json(capsys):
    scenarios = run_json(capsys, "scenarios")
    names = {s["name"] for s in scenarios}
    assert "bench_static" in names and all(set(s) == {"name", "kind", "description"} for s in scenarios)
    presets = run_json(capsys, "presets")
    mems = next(d for d in presets if d["name"] == "consumer_mems")
    assert set(mems) == {"name", "kind", "rate_hz", "arw_deg_sqrt_h", "bias_instability_deg_h", "resembles"}
    assert mems["rate_hz"] == 1000 and mems["arw_deg_sqrt_h"] > 0
    # The text stays a table.
    assert main(["presets"]) == 0
    assert capsys.readouterr().out.startswith("name")


def test_info_json_counts_and_rates(capsys, log):
    info = run_json(capsys, "info", str(log))
    assert info["path"] == str(log) and info["profile"] == "ros2" and not info["truncated"]
    (device,) = info["devices"]
    assert device["samples"] == 5000 and device["topics"]["imu"] == "/imu"
    assert "scenario" not in device["metadata"] and device["metadata"]["version"]
    topics = {t["topic"]: t for t in info["topics"]}
    imu = topics["/imu"]
    assert imu["count"] == 5000 and imu["schema"] == "sensor_msgs/msg/Imu"
    assert imu["span_s"] == pytest.approx(imu["last_stamp_s"] - imu["first_stamp_s"])
    # (count - 1) / span: 1000 Hz within one sample over the span.
    assert abs(imu["rate_hz"] - 1000) <= 1 / imu["span_s"]
    assert imu["rate_hz"] == pytest.approx(1000, rel=1e-6)
    assert imu["median_interval_s"] == pytest.approx(1e-3, rel=1e-9)
    assert imu["gaps"] == 0 and imu["longest_gap_s"] is None
    assert sum(t["count"] for t in info["topics"]) == info["message_count"]
    with_configs = run_json(capsys, "info", str(log), "--configs")
    assert 'kind = "static"' in with_configs["devices"][0]["metadata"]["scenario"]
    # The text: the device line as before, plus one line per topic.
    assert main(["info", str(log)]) == 0
    text = capsys.readouterr().out
    assert "device 'consumer_mems': 5000 samples over 4.999 s (1000 Hz)" in text
    assert "complete (summary and indexes)" in text and "topics (log times):" in text
    # simulate's stamps start at its fixed epoch, 2025-01-01T00:00:00Z; the first sample is 1 ms after it.
    assert (
        "/imu                         5000 messages, from 2025-01-01T00:00:00.001000Z for 4.999 s (1000 Hz), no gaps"
        in text
    )


def test_info_reports_a_gap(tmp_path, capsys):
    path = tmp_path / "gap.mcap"
    with McapLogWriter(path, chunk_size=4096) as writer:  # small chunks: intervals across chunks count
        writer.write(_samples(np.arange(1000) * 1e-3))  # 0 .. 0.999 s
        writer.write(_samples(1.5 + np.arange(500) * 1e-3))  # a hole of 0.501 s
    (imu,) = [t for t in topic_stats(path) if t.topic == "/imu"]
    assert imu.count == 1500 and imu.gaps == 1
    assert imu.longest_gap_s == pytest.approx(0.501, abs=1e-9)
    assert imu.median_interval_s == pytest.approx(1e-3, rel=1e-9)
    assert imu.rate_hz == pytest.approx(1499 / 1.999)
    info = run_json(capsys, "info", str(path))
    (entry,) = [t for t in info["topics"] if t["topic"] == "/imu"]
    assert entry["gaps"] == 1 and entry["longest_gap_s"] == pytest.approx(0.501, abs=1e-9)
    assert main(["info", str(path)]) == 0
    assert "1 gaps (longest 0.501 s)" in capsys.readouterr().out


def test_estimate_json(tmp_path, capsys, log):
    out = tmp_path / "est.mcap"
    document = run_json(capsys, "estimate", str(log), "--out", str(out), "--filter", "madgwick")
    assert document["out"] == str(out) and out.exists()
    assert document["devices"][0]["samples"] == 5000 and document["devices"][0]["filter"]
    assert document["topics"][0]["topic_out"].endswith("/estimate/imu") and document["topics"][0]["estimates"] == 5000


def test_truncated_log_warns_on_one_line_and_q_silences_it(tmp_path, log):
    cut = tmp_path / "cut.mcap"
    data = log.read_bytes()
    cut.write_bytes(data[: int(len(data) * 0.6)])
    loud = gyroemu("info", str(cut))
    assert loud.returncode == 0, loud.stderr
    lines = loud.stderr.splitlines()
    truncated = [line for line in lines if "truncated at byte" in line]
    assert len(truncated) == 1 and truncated[0].startswith(f"gyroemu: warning: {cut}: truncated at byte")
    assert all(line.startswith("gyroemu: warning: ") for line in lines)  # no file:line, no source line
    assert "TRUNCATED" in loud.stdout
    quiet = gyroemu("-q", "info", str(cut))
    assert quiet.returncode == 0 and quiet.stderr == "" and quiet.stdout == loud.stdout


def test_logging_is_set_up_only_while_main_runs(capsys):
    import logging

    before = (list(logging.getLogger("py.warnings").handlers), warnings.showwarning)
    with cli_logging(logging.WARNING), warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings.warn("first line\nsecond line", LogWarning, stacklevel=1)
        logging.getLogger("gyroemu.test").info("not shown")
    assert capsys.readouterr().err == "gyroemu: warning: first line second line\n"
    with cli_logging(logging.DEBUG):
        logging.getLogger("gyroemu.test").debug("shown")
    assert capsys.readouterr().err == "gyroemu: debug: shown\n"
    assert (list(logging.getLogger("py.warnings").handlers), warnings.showwarning) == before


def test_quiet_and_verbose_are_global_options():
    args = build_parser().parse_args(["-q", "scenarios"])
    assert args.quiet and not args.verbose
    args = build_parser().parse_args(["-v", "info", "x.mcap"])
    assert args.verbose and not args.quiet


def test_bash_completion(tmp_path, capsys):
    assert main(["completion", "bash"]) == 0
    script = capsys.readouterr().out
    for name in SUBCOMMANDS:
        assert f" {name}" in script
    assert "complete -o filenames -o bashdefault -F _gyroemu gyroemu" in script
    path = tmp_path / "gyroemu.bash"
    path.write_text(script)
    assert subprocess.run(["bash", "-n", str(path)], capture_output=True).returncode == 0
    # Completing: subcommands, then the subcommand's options, then an option's choices.
    probe = (
        f"source {path}\n"
        'COMP_WORDS=(gyroemu si); COMP_CWORD=1; _gyroemu; echo "${COMPREPLY[*]}"\n'
        'COMP_WORDS=(gyroemu -q info --j); COMP_CWORD=3; _gyroemu; echo "${COMPREPLY[*]}"\n'
        'COMP_WORDS=(gyroemu stream --mode ""); COMP_CWORD=3; _gyroemu; echo "${COMPREPLY[*]}"\n'
    )
    result = subprocess.run(["bash", "-c", probe], capture_output=True, text=True, cwd=tmp_path)
    assert result.stdout.splitlines() == ["simulate", "--json", "peer client"], result.stderr


def test_zsh_completion(tmp_path, capsys):
    assert main(["completion", "zsh"]) == 0
    script = capsys.readouterr().out
    assert script.startswith("#compdef gyroemu\n")
    for name in SUBCOMMANDS:
        assert f"'{name}:" in script and f"                {name})" in script
    assert "'--mode[zenoh session mode]:MODE:(peer client)'" in script
    if shutil.which("zsh"):
        path = tmp_path / "_gyroemu"
        path.write_text(script)
        assert subprocess.run(["zsh", "-n", str(path)], capture_output=True).returncode == 0

"""``gyroemu demo``: its inputs are never overwritten, and a signal in its live stage stops it.

The live stage is played here without zenoh: a stand-in recorder process writes a few bytes to the
file it is told, and a stand-in stream stops on a signal it raises itself, through the stream's own
handlers (:func:`gyroemu.pipelines.transport.zenoh_io.stop_on_signals`), as Ctrl-C or ``kill`` would.
"""

from __future__ import annotations

import shutil
import signal
import subprocess
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from gyroemu.pipelines.jobs import demo
from gyroemu.pipelines.jobs.demo import DemoError, check_options

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def test_an_input_is_never_overwritten_even_with_force(tmp_path):
    """A file the demo writes (demo.mcap, bench/bench.md, bench/bench.json, bench/demo.mcap.png) that is
    its --scenario file (by any path to it: a symbolic link) or a recorded scenario's motion file: refused
    naming --out before any work, even with --force."""
    out = tmp_path / "demo"
    (out / "bench").mkdir(parents=True)
    shutil.copy(CONFIGS / "scenarios" / "heavy_top.toml", out / "demo.mcap")
    with pytest.raises(DemoError, match=f"argument --out: {out / 'demo.mcap'} is an input"):
        check_options(str(out / "demo.mcap"), 1.0, out, 1.0, force=True)
    scenario = tmp_path / "top.toml"
    (out / "demo.mcap").rename(scenario)
    (out / "bench" / "bench.json").symlink_to(scenario)
    with pytest.raises(DemoError, match=f"argument --out: {out / 'bench' / 'bench.json'} is an input"):
        check_options(str(scenario), 1.0, out, 1.0, force=True)
    (out / "bench" / "bench.json").unlink()
    motion = out / "bench" / "demo.mcap.png"
    shutil.copy(CONFIGS / "scenarios" / "recorded_motion.csv", motion)
    recorded = tmp_path / "recorded.toml"
    recorded.write_text(f'kind = "recorded"\ndescription = "d"\npath = "{motion}"\nformat = "csv"\n')
    with pytest.raises(DemoError, match=f"argument --out: {motion} is an input"):
        check_options(str(recorded), 1.0, out, 1.0, force=True)
    check_options(str(scenario), 1.0, out, 1.0, force=True)  # the plot is no input of this one


class _Recorder:
    """A stand-in ``gyroemu record`` process: writes a partial log to its ``--out`` at once."""

    def __init__(self, argv: list[str], **kwargs: Any) -> None:
        self.path = Path(argv[argv.index("--out") + 1])
        self.path.write_bytes(b"a partial log")
        self.returncode: int | None = None

    def poll(self) -> int | None:
        return self.returncode

    def send_signal(self, sig: int) -> None:
        self.returncode = 0

    def communicate(self, timeout: float | None = None) -> tuple[str, None]:
        return f"record: 12 messages -> {self.path}\n", None

    def kill(self) -> None:
        self.returncode = -9

    def wait(self) -> int | None:
        return self.returncode


@pytest.mark.parametrize(("sig", "status"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_in_the_live_stage_stops_the_demo(tmp_path, monkeypatch, capsys, sig, status):
    """SIGINT (130) or SIGTERM (143) while the stream runs: the demo stops with that status, no bench
    runs, and no partial log is left under demo.mcap (an earlier demo's stays as it was), nor any
    hidden file; it was exit 0, 'the live stage failed', and a partial demo.mcap a rerun refused."""
    from gyroemu.pipelines.transport import stream
    from gyroemu.pipelines.transport.zenoh_io import stop_on_signals

    def run_stream(options: Any, out: Any) -> int:  # as the stream's LiveSession.stop_status says it
        with stop_on_signals() as stopping:
            signal.raise_signal(sig)
            return 0 if not stopping else 143 if stopping[0] == signal.SIGTERM else 130

    def no_bench(*args: Any, **kwargs: Any) -> None:
        raise AssertionError("the bench ran after the demo was stopped")

    monkeypatch.setattr(stream, "run_stream", run_stream)
    monkeypatch.setattr(
        demo, "subprocess", SimpleNamespace(Popen=_Recorder, PIPE=subprocess.PIPE, STDOUT=subprocess.STDOUT)
    )
    monkeypatch.setattr(demo.time, "sleep", lambda s: None)
    monkeypatch.setattr("gyroemu.pipelines.jobs.bench.run_bench", no_bench)
    out = tmp_path / "demo"
    out.mkdir()
    (out / "demo.mcap").write_bytes(b"an earlier demo's log")
    assert demo._live_and_bench(out, 20.0) == status
    assert sorted(p.name for p in out.iterdir()) == ["demo.mcap"]
    assert (out / "demo.mcap").read_bytes() == b"an earlier demo's log"
    printed = capsys.readouterr().out
    assert "the live stage was stopped" in printed and f"-> {out / 'demo.mcap'}" in printed

"""``gyroemu simulate``'s progress bar: drawn on a terminal (a pseudo-terminal here), absent otherwise.

No timing is asserted: only what is written where.
"""

import fcntl
import os
import select
import struct
import subprocess
import sys
import termios
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
ARGS = ["simulate", "--scenario", "heavy_top", "--device", "consumer_mems", "--duration", "2"]


def _run_on_pty(args) -> tuple[int, str, str]:
    """Run ``gyroemu ARGS`` with stderr on a pseudo-terminal (120 columns); returns (status, stdout, terminal)."""
    master, slave = os.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 120, 0, 0))
    proc = subprocess.Popen([sys.executable, "-m", "gyroemu", *args], cwd=ROOT, stderr=slave, stdout=subprocess.PIPE)
    os.close(slave)
    seen = b""
    try:
        while True:
            ready, _, _ = select.select([master], [], [], 0.2)
            if ready:
                try:
                    data = os.read(master, 1 << 16)
                except OSError:  # EIO: the child closed the terminal
                    break
                if not data:
                    break
                seen += data
            elif proc.poll() is not None:
                break
        out = proc.stdout.read().decode()
        status = proc.wait(60)
    finally:
        os.close(master)
        if proc.poll() is None:
            proc.kill()
    return status, out, seen.decode("utf-8", errors="replace")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="pseudo-terminal test for Linux")
def test_bar_on_a_terminal_counts_samples_or_names_each_phase(tmp_path):
    status, out, terminal = _run_on_pty([*ARGS, "--out", str(tmp_path / "a.mcap")])
    assert status == 0 and "-> " in out
    samples = int(out.split(" samples of ")[0].split(", ")[-1])  # "... truth samples, N samples of ..."
    assert "simulate:" in terminal and " samples" in terminal, terminal
    from tqdm import tqdm

    assert f"/{tqdm.format_sizeof(samples)}" in terminal, terminal  # the run's total, as tqdm scales it
    assert "samples/s" not in out and "simulate:" not in out  # the bar never goes to stdout
    status, out, terminal = _run_on_pty(
        ["simulate", "--scenario", "heavy_top", "--duration", "2", "--out", str(tmp_path / "t.npz")]
    )
    assert status == 0 and "simulate: truth" in terminal and "/2 phases" in terminal and "measure" not in terminal


def test_no_bar_when_stderr_is_not_a_terminal(tmp_path):
    run = subprocess.run(
        [sys.executable, "-m", "gyroemu", *ARGS, "--out", str(tmp_path / "a.mcap")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert run.returncode == 0 and run.stderr == "", run.stderr
    assert (tmp_path / "a.mcap").exists()

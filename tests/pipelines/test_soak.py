"""The three-process soak of ``tests/benchmarks/soak_three_process.py``, short: publisher, router and
recorder as separate ``gyroemu`` processes, 15 s of a 1 kHz stream through the router; nothing lost,
nothing duplicated (sequence numbers and header stamps), the recorded bytes equal to what the library
encodes for the same scenario, device and seed. The 10-minute run is the script's default.

Bounded in time (about 25 s on an idle machine); the script stops every process it starts.
"""

import importlib.util
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # long statistical or multi-process runs: `pytest -m slow`

pytest.importorskip("zenoh")

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "soak_three_process.py"


def test_three_process_soak_short(tmp_path, capsys):
    spec = importlib.util.spec_from_file_location("soak_three_process", SCRIPT)
    soak = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(soak)
    ok = soak.run(15.0, 3, tmp_path)
    out = capsys.readouterr().out
    print(out)
    assert ok, out
    assert out.count("missing 0, duplicates 0, out of order 0") == 4
    assert out.count("bytes identical") == 4

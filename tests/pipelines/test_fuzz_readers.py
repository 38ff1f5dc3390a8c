"""Fuzzed readers: config files and MCAP logs that are random, truncated or corrupt.

Whatever the input, a reader either succeeds or raises one of gyroemu's own errors
(:class:`gyroemu.errors.GyroemuError`: ``ConfigError``, ``LogError``; the command line returns 2 for
them, or exits with 2 for bad usage). Nothing else may escape, nothing may hang (hypothesis'
``deadline``) and nothing may allocate far more than the file (a length field read from the file is
checked against the file's size): :func:`bounded` measures the peak of Python's and numpy's allocations
with ``tracemalloc``.

- Configs: built-in device and scenario files with keys replaced by random scalars, arrays and tables,
  deleted, or joined by unknown keys; and wholly random tables. Each goes through ``*_from_dict`` and,
  serialised with ``tomli_w``, through ``load_*`` (plus random bytes as a TOML file).
- Logs: a small valid log (``run_simulate``, bench_static on consumer_mems, 1 s), truncated, with bit
  flips, with a record's length field overwritten, with a chunk's inner records corrupted (rewritten as
  an uncompressed chunk, so its content is what the reader sees), or random bytes. Each goes through
  ``read_mcap``, ``gyroemu info``, ``gyroemu estimate``, ``allan_of_log`` and ``iter_mcap_batches`` (the
  reader ``gyroemu replay`` publishes from, after validating the file with ``read_mcap``; replay itself
  opens a zenoh session, so it is not run here).

The fast tier runs a few cases per property (:data:`FAST`, derandomised); ``pytest -m slow`` runs
:data:`SLOW` (many more, random).
"""

from __future__ import annotations

import hashlib
import itertools
import os
import struct
import tomllib
import traceback
import tracemalloc
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import tomli_w
from cli_runs import run_cli
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gyroemu.dynamics.config import config_dir
from gyroemu.dynamics.scenarios import load_scenario, scenario_from_dict
from gyroemu.errors import ConfigError, GyroemuError
from gyroemu.pipelines.formats.mcap_log import read_mcap
from gyroemu.pipelines.formats.mcap_records import iter_mcap_batches
from gyroemu.pipelines.jobs.allan import allan_of_log
from gyroemu.pipelines.jobs.simulate import SimulateOptions, run_simulate
from gyroemu.sensors import device_from_dict, load_device

_COMMON = dict(
    deadline=5000,  # ms per case: no reader may hang on a corrupt file
    database=None,  # nothing written into the checkout
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
)
FAST = settings(max_examples=25, derandomize=True, **_COMMON)
SLOW = settings(max_examples=500, **_COMMON)

#: Peak allocation allowed to one reader call: the log is 0.2 MB, its decoded arrays and the estimate a
#: few MB; a length field trusted from a corrupt file would ask for GBs.
MEMORY_LIMIT = 256 << 20

MAGIC = b"\x89MCAP0\r\n"
_CASE = itertools.count()


#: Crashes found by these tests in files outside the change that added them, reported to their owners:
#: (exception type, file, function) of a gyroemu frame a known, not yet fixed crash passes; the four
#: found while writing these tests are fixed (the tests below the readers' hold them).
KNOWN_CRASHES: set[tuple[str, str, str]] = set()


def crash_sites(error: BaseException) -> set[tuple[str, str, str]]:
    """(type, file relative to the checkout, function) of each gyroemu frame that ``error`` passed."""
    root = Path(__file__).resolve().parents[2]
    sites = set()
    for frame in traceback.extract_tb(error.__traceback__):
        path = Path(frame.filename).resolve()
        if path.is_relative_to(root) and not path.is_relative_to(root / "tests"):
            sites.add((type(error).__name__, path.relative_to(root).as_posix(), frame.name))
    return sites


def bounded(call: Callable[[], Any], allowed: tuple[type[BaseException], ...] = (GyroemuError,)) -> Any:
    """``call()`` with its peak traced allocation checked against :data:`MEMORY_LIMIT`; only ``allowed``
    errors (gyroemu's own) and :data:`KNOWN_CRASHES` may escape (returned, not raised)."""
    tracemalloc.start()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                result = call()
            except allowed as e:
                result = e
            except Exception as e:
                if not crash_sites(e) & KNOWN_CRASHES:
                    raise
                result = e
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < MEMORY_LIMIT, f"peak allocation {peak / 2**20:.0f} MB"
    return result


def run_status(argv: list[str]) -> int:
    """``gyroemu argv``'s exit status, which must be 0 or 2 (a ``SystemExit(2)`` of bad usage counts as 2)."""
    status, out, err = run_cli(argv)
    assert status in (0, 2), (status, (out + err)[-2000:])
    return status


# -- configs ---------------------------------------------------------------------------------------

_KEYS = st.text(alphabet="abcdefghijklmnopqrstuvwxyz_0123456789", min_size=1, max_size=12)
_SCALARS = st.one_of(
    st.booleans(),
    st.integers(min_value=-(2**63), max_value=2**63 - 1),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=20),
    st.sampled_from(["mems", "fog", "rlg", "static", "rate_table", "", "x", "heavy_top", "consumer_mems"]),
)
_VALUES = st.recursive(
    _SCALARS,
    lambda inner: st.one_of(st.lists(inner, max_size=8), st.dictionaries(_KEYS, inner, max_size=4)),
    max_leaves=12,
)


def _toml_names(kind: str) -> list[str]:
    return sorted(p.stem for p in (config_dir() / kind).glob("*.toml"))


def _paths(table: dict, prefix: tuple = ()) -> list[tuple]:
    """Every key path of a nested table."""
    out = []
    for key, value in table.items():
        out.append((*prefix, key))
        if isinstance(value, dict):
            out.extend(_paths(value, (*prefix, key)))
    return out


@st.composite
def mutated_config(draw: st.DrawFn, kind: str) -> dict:
    """A built-in config of ``kind`` ("devices" or "scenarios") with a few keys changed, or a random table."""
    if draw(st.integers(0, 9)) == 0:
        return draw(st.dictionaries(st.one_of(_KEYS, st.sampled_from(["kind", "rate_hz", "gyro"])), _VALUES))
    name = draw(st.sampled_from(_toml_names(kind)))
    table = tomllib.loads((config_dir() / kind / f"{name}.toml").read_text())
    for _ in range(draw(st.integers(1, 4))):
        paths = _paths(table)
        action = draw(st.sampled_from(["replace", "delete", "add"]))
        if not paths:
            action = "add"
        where = table
        if action != "add" or draw(st.booleans()):
            path = draw(st.sampled_from(paths)) if paths else ()
            for key in path[:-1]:
                where = where[key]
            if action == "delete":
                del where[path[-1]]
                continue
            if action == "replace":
                where[path[-1]] = draw(_VALUES)
                continue
            if isinstance(where.get(path[-1]), dict):
                where = where[path[-1]]
        where[draw(_KEYS)] = draw(_VALUES)
    return table


def _write_toml(folder: Path, table: dict) -> Path | None:
    """``table`` as a TOML file (None when TOML cannot hold it: NaN is fine, but not e.g. None)."""
    try:
        text = tomli_w.dumps(table)
    except (TypeError, ValueError):
        return None
    path = folder / f"case{next(_CASE)}.toml"
    path.write_text(text, encoding="utf-8")
    return path


def check_device(folder: Path, table: dict) -> None:
    bounded(lambda: device_from_dict(table, name="fuzz"))
    path = _write_toml(folder, table)
    if path is not None:
        bounded(lambda: load_device(path))


def check_scenario(folder: Path, table: dict) -> None:
    bounded(lambda: scenario_from_dict(table, name="fuzz"))
    path = _write_toml(folder, table)
    if path is not None:
        bounded(lambda: load_scenario(path))


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("fuzz")


@FAST
@given(table=mutated_config("devices"))
def test_device_configs(folder: Path, table: dict) -> None:
    check_device(folder, table)


@FAST
@given(table=mutated_config("scenarios"))
def test_scenario_configs(folder: Path, table: dict) -> None:
    check_scenario(folder, table)


@FAST
@given(raw=st.binary(max_size=300) | st.text(max_size=300).map(str.encode))
def test_random_bytes_as_config_files(folder: Path, raw: bytes) -> None:
    path = folder / f"case{next(_CASE)}.toml"
    path.write_bytes(raw)
    bounded(lambda: load_device(path))
    bounded(lambda: load_scenario(path))


@pytest.mark.slow
@SLOW
@given(device=mutated_config("devices"), scenario=mutated_config("scenarios"))
def test_configs_many(folder: Path, device: dict, scenario: dict) -> None:
    check_device(folder, device)
    check_scenario(folder, scenario)


# -- MCAP logs -------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def valid_log(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    """The bytes of a small valid gyroemu log: bench_static on consumer_mems, 1 s."""
    out = tmp_path_factory.mktemp("log") / "base.mcap"
    run_simulate(SimulateOptions("bench_static", out, device="consumer_mems", duration=1.0, progress=False))
    data = out.read_bytes()
    assert read_mcap(out).devices, "the base log reads"
    return data


def _records(data: bytes, start: int = 0) -> list[tuple[int, int, int]]:
    """(position, opcode, length) of the records from ``start`` (MCAP: opcode u8, length u64, content)."""
    out, p = [], start
    while p + 9 <= len(data):
        opcode, length = struct.unpack_from("<BQ", data, p)
        if p + 9 + length > len(data):
            break
        out.append((p, opcode, length))
        p += 9 + length
    return out


def _chunk_contents(data: bytes, p: int, length: int) -> tuple[bytes, bytes]:
    """(the fields before the records' length, the decompressed records) of the Chunk record at ``p``."""
    import zstandard

    content = data[p + 9 : p + 9 + length]
    clen = struct.unpack_from("<I", content, 28)[0]
    compression = content[32 : 32 + clen].decode()
    q = 32 + clen
    (rlen,) = struct.unpack_from("<Q", content, q)
    packed = content[q + 8 : q + 8 + rlen]
    records = zstandard.ZstdDecompressor().decompress(packed) if compression == "zstd" else packed
    return content[:16], records


def _chunk(head: bytes, records: bytes) -> bytes:
    """A Chunk record (uncompressed, no CRC) holding ``records``."""
    content = head + struct.pack("<QI", len(records), 0) + struct.pack("<I", 0) + struct.pack("<Q", len(records))
    return struct.pack("<BQ", 0x06, len(content) + len(records)) + content + records


def _flip(data: bytes, draw: st.DrawFn, at_most: int = 8) -> bytes:
    out = bytearray(data)
    for _ in range(draw(st.integers(1, at_most))):
        i = draw(st.integers(0, len(out) - 1))
        out[i] ^= 1 << draw(st.integers(0, 7))
    return bytes(out)


_LENGTHS = st.one_of(st.integers(0, 2**64 - 1), st.sampled_from([0, 1, 8, 21, 22, 2**31, 2**32 + 5, 2**63, 2**64 - 1]))


def _set_length(data: bytes, draw: st.DrawFn, records: list[tuple[int, int, int]]) -> bytes:
    p = draw(st.sampled_from(records))[0]
    return data[: p + 1] + struct.pack("<Q", draw(_LENGTHS)) + data[p + 9 :]


class LogCase:
    """A corrupt log: its bytes and how they were made (the repr hypothesis prints for a failure; the
    bytes are written to the file it names when ``GYROEMU_FUZZ_KEEP`` names a folder)."""

    def __init__(self, how: str, data: bytes) -> None:
        self.how, self.data = how, data

    def __repr__(self) -> str:
        digest = hashlib.sha1(self.data).hexdigest()[:12]
        keep = os.environ.get("GYROEMU_FUZZ_KEEP")
        if keep:
            (Path(keep) / f"{digest}.mcap").write_bytes(self.data)
        return f"LogCase({self.how!r}, {len(self.data)} bytes, sha1 {digest})"


@st.composite
def corrupted_log(draw: st.DrawFn, base: bytes) -> LogCase:
    """``base`` corrupted in one of several ways (module notes)."""
    kind = draw(st.sampled_from(["truncate", "flip", "length", "chunk", "random"]))
    if kind == "truncate":
        at = draw(st.integers(0, len(base) - 1))
        return LogCase(f"truncated at {at}", base[:at])
    if kind == "flip":
        return LogCase("bit flips", _flip(base, draw))
    if kind == "random":
        return LogCase("random bytes", draw(st.binary(max_size=400) | st.binary(max_size=64).map(lambda b: MAGIC + b)))
    top = _records(base, 8)
    if kind == "length":
        return LogCase("a record's length", _set_length(base, draw, top))
    chunks = [r for r in top if r[1] == 0x06]
    p, _, length = draw(st.sampled_from(chunks))
    head, records = _chunk_contents(base, p, length)
    how = draw(st.sampled_from(["flip", "length", "truncate", "field"]))
    if how == "flip":
        records = _flip(records, draw, 32)
    elif how == "length":
        records = _set_length(records, draw, _records(records))
    elif how == "truncate":
        records = records[: draw(st.integers(0, len(records)))]
    else:  # overwrite 8 bytes anywhere inside (a time stamp, a channel id, a sequence, a payload)
        i = draw(st.integers(0, max(0, len(records) - 8)))
        records = records[:i] + draw(st.binary(min_size=8, max_size=8)) + records[i + 8 :]
    return LogCase(f"chunk at {p}: {how}", base[:p] + _chunk(head, records) + base[p + 9 + length :])


def _readers(out: Path) -> dict[str, Callable[[Path], None]]:
    def estimate(path: Path) -> None:
        run_status(["estimate", str(path), "--out", str(out / f"est{next(_CASE)}.mcap")])

    def batches(path: Path) -> None:
        for _ in iter_mcap_batches(path):
            pass

    return {
        "read_mcap": read_mcap,
        "info": lambda path: run_status(["info", str(path), "--configs"]),
        "estimate": estimate,
        "allan": allan_of_log,
        "iter_mcap_batches": batches,
    }


READERS = ["read_mcap", "info", "estimate", "allan", "iter_mcap_batches"]


def check_log(folder: Path, data: bytes, reader: str) -> None:
    """``reader`` on ``data`` written to a file: only gyroemu's errors (``allan_of_log``'s
    :class:`AllanLogError` is one of them, a :class:`gyroemu.errors.LogError`)."""
    path = folder / f"case{next(_CASE)}.mcap"
    path.write_bytes(data)
    allowed = (GyroemuError,)
    try:
        bounded(lambda: _readers(folder)[reader](path), allowed)
    finally:
        path.unlink()


def test_the_base_log_reads_with_every_reader(folder: Path, valid_log: bytes) -> None:
    for reader in READERS:
        check_log(folder, valid_log, reader)
    path = folder / "base.mcap"
    path.write_bytes(valid_log)
    assert run_status(["info", str(path)]) == 0


@pytest.mark.parametrize("reader", READERS)
def test_corrupt_logs(folder: Path, valid_log: bytes, reader: str) -> None:
    @FAST
    @given(case=corrupted_log(valid_log))
    def prop(case: LogCase) -> None:
        check_log(folder, case.data, reader)

    prop()


@pytest.mark.slow
@pytest.mark.parametrize("reader", READERS)
def test_corrupt_logs_many(folder: Path, valid_log: bytes, reader: str) -> None:
    @SLOW
    @given(case=corrupted_log(valid_log))
    def prop(case: LogCase) -> None:
        check_log(folder, case.data, reader)

    prop()


# -- BROAD imports (HDF5) --------------------------------------------------------------------------


@pytest.fixture(scope="module")
def valid_trial(folder: Path) -> bytes:
    """The bytes of a small BROAD-like trial (HDF5): the datasets and attribute ``read_broad`` needs."""
    import h5py
    import numpy as np

    rng = np.random.default_rng(3)
    n = 50
    path = folder / "trial.hdf5"
    with h5py.File(path, "w") as f:
        for name, width in {"imu_gyr": 3, "imu_acc": 3, "imu_mag": 3, "opt_quat": 4, "opt_pos": 3}.items():
            values = rng.normal(size=(n, width))
            if name == "opt_quat":  # unit quaternions: read_broad refuses a row that is no rotation
                values /= np.linalg.norm(values, axis=1, keepdims=True)
            f.create_dataset(name, data=values)
        f.create_dataset("movement", data=np.arange(n) % 7 < 4)
        f.attrs["sampling_rate"] = 100.0
    return path.read_bytes()


@st.composite
def corrupted_trial(draw: st.DrawFn, base: bytes) -> LogCase:
    if draw(st.booleans()):
        at = draw(st.integers(0, len(base) - 1))
        return LogCase(f"truncated at {at}", base[:at])
    return LogCase("bit flips", _flip(base, draw))


def check_import(folder: Path, data: bytes) -> None:
    source = folder / f"case{next(_CASE)}.hdf5"
    source.write_bytes(data)
    out = folder / f"imported{next(_CASE)}.mcap"
    try:
        bounded(lambda: run_status(["import", "broad", str(source), "--out", str(out), "--force"]))
    finally:
        source.unlink()
        out.unlink(missing_ok=True)


def test_the_base_trial_imports(folder: Path, valid_trial: bytes) -> None:
    source = folder / "trial_copy.hdf5"
    source.write_bytes(valid_trial)
    assert run_status(["import", "broad", str(source), "--out", str(folder / "trial.mcap"), "--force"]) == 0


@FAST
@given(data=st.data())
def test_corrupt_broad_trials(folder: Path, valid_trial: bytes, data: st.DataObject) -> None:
    check_import(folder, data.draw(corrupted_trial(valid_trial)).data)


@pytest.mark.slow
@SLOW
@given(data=st.data())
def test_corrupt_broad_trials_many(folder: Path, valid_trial: bytes, data: st.DataObject) -> None:
    check_import(folder, data.draw(corrupted_trial(valid_trial)).data)


# -- crashes outside these readers' files (KNOWN_CRASHES) -----------------------------------------


def test_a_device_with_a_list_as_gyro_kind_is_a_config_error() -> None:
    table = tomllib.loads((config_dir() / "devices" / "consumer_mems.toml").read_text())
    table["gyro"]["mechanism"]["kind"] = ["mems"]
    with pytest.raises(ConfigError, match="kind"):
        device_from_dict(table)


def test_a_scenario_with_a_table_as_kind_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match="kind"):
        scenario_from_dict({"kind": {"static": True}})


def test_allan_of_a_log_with_a_corrupt_device_config_is_a_log_error(folder: Path, valid_log: bytes) -> None:
    good, bad = b"rate_hz = 1000.0\noutput", b"rate_hz = =000.0\noutput"  # same length: offsets hold
    assert good in valid_log
    path = folder / "corrupt_device_toml.mcap"
    path.write_bytes(valid_log.replace(good, bad))
    with pytest.raises(GyroemuError):
        allan_of_log(path)


def test_estimate_of_a_log_with_a_huge_accelerometer_sample_ends_cleanly(folder: Path, valid_log: bytes) -> None:
    base = folder / "huge_accel_base.mcap"
    base.write_bytes(valid_log)
    first = read_mcap(base).devices["consumer_mems"].samples.accel[0, 1]
    p, _, length = next(r for r in _records(valid_log, 8) if r[1] == 0x06)
    head, records = _chunk_contents(valid_log, p, length)
    assert records.count(struct.pack("<d", first)) >= 1
    records = records.replace(struct.pack("<d", first), struct.pack("<d", -9.14e232), 1)
    path = folder / "huge_accel.mcap"
    path.write_bytes(valid_log[:p] + _chunk(head, records) + valid_log[p + 9 + length :])
    # A level start with the tilt unknown, or a refusal (exit 2): never a traceback.
    run_status(["estimate", str(path), "--out", str(folder / "huge_accel_estimate.mcap"), "--force"])


def _zstd_chunk(head: bytes, records: bytes, usize: int, frame_size: int | None) -> bytes:
    """A zstd Chunk record of ``records`` declaring ``usize`` bytes, its frame declaring ``frame_size``
    (None: a frame without a content size). No CRC."""
    import zstandard

    packed = bytearray(zstandard.ZstdCompressor(write_content_size=frame_size is not None).compress(records))
    if frame_size is not None:  # the frame header's content size field: 4 bytes for these sizes
        descriptor = packed[4]
        assert descriptor >> 6 == 2 and descriptor & 0x23 == 0x20, "single segment, no dictionary, 4-byte size"
        packed[5:9] = struct.pack("<I", frame_size)
    compression = b"zstd"
    content = (
        head
        + struct.pack("<QI", usize, 0)
        + struct.pack("<I", len(compression))
        + compression
        + struct.pack("<Q", len(packed))
    )
    return struct.pack("<BQ", 0x06, len(content) + len(packed)) + content + bytes(packed)


@pytest.mark.parametrize(
    "declared, frame",
    [(1 << 40, None), ("records", 0xFFFFFFF0), (0xFFFFFFF0, 0xFFFFFFF0)],
    ids=["chunk size 1 TB", "frame size 4 GB", "both 4 GB"],
)
def test_a_corrupt_chunk_size_allocates_nothing_near_it(
    folder: Path, valid_log: bytes, declared: int | str, frame: int | None
) -> None:
    """Found by review (the fuzzed bits rarely land there): zstandard sizes its output by the frame's
    content size, or by ``max_output_size`` when the frame has none; both came from the file."""
    p, _, length = next(r for r in _records(valid_log, 8) if r[1] == 0x06)
    head, records = _chunk_contents(valid_log, p, length)
    usize = len(records) if declared == "records" else int(declared)
    path = folder / f"zstd_size{next(_CASE)}.mcap"
    path.write_bytes(valid_log[:p] + _zstd_chunk(head, records, usize, frame) + valid_log[p + 9 + length :])
    error = bounded(lambda: read_mcap(path))
    assert isinstance(error, GyroemuError) and "corrupt chunk" in str(error), error

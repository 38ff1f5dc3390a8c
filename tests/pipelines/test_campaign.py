"""Campaigns (gyroemu.pipelines.campaign, jobs.campaign): the campaign file, the Parquet store and its
resume, and a tiny campaign on an in-process Dask cluster (threads, no worker processes).

What is held, and why it could be false
---------------------------------------
- A bad campaign file fails before any work, naming the file and the key (exit status 2, no output).
- The store's rows are exactly the bench's: each (seed, filter) row of a task equals what
  :func:`run_bench` gives for the same cell and seed, to the bit (both are the same deterministic
  computation on the same seeded draws; only timings differ).
- Resume: a part removed is the only task run again; the rows after are the rows before (same keys,
  same numbers), one per (cell, seed, filter).
- A task that raises is reported with its error and the others' rows are stored.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import pytest

from gyroemu.errors import ConfigError
from gyroemu.pipelines import cli
from gyroemu.pipelines.campaign import PartStore, consecutive, load_campaign, row_schema, run_tasks

pa = pytest.importorskip("pyarrow")


def _write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


TINY = """
name = "tiny"
scenarios = ["smooth_manoeuvre"]
devices = ["consumer_mems", "tactical_mems"]
durations_s = [0.5]
seed_range = { start = 7, count = 3 }
filters = ["madgwick", "mahony"]
modes = ["9D", "6D"]
seeds_per_task = 2
"""


# --- the campaign file --------------------------------------------------------------------------------


def test_grid_and_tasks(tmp_path):
    c = load_campaign(_write(tmp_path / "c.toml", TINY))
    # consumer_mems has a magnetometer: 9D and 6D; tactical_mems has none: one 6D cell, not two alike.
    assert [(Path(x.device).stem, x.mode) for x in c.cells] == [
        ("consumer_mems", "9D"),
        ("consumer_mems", "6D"),
        ("tactical_mems", "6D"),
    ]
    assert c.seeds == (7, 8, 9)
    assert [t.seeds for t in c.tasks[:2]] == [(7, 8), (9,)]
    assert len(c.tasks) == 6 and c.runs == 3 * 3 * 2
    assert len({t.key for t in c.tasks}) == 6
    assert c.tasks[0].key == load_campaign(tmp_path / "c.toml").tasks[0].key  # stable across loads
    assert consecutive((1, 2, 3, 7, 9, 10)) == [(1, 3), (7, 1), (9, 2)]


def test_task_key_follows_the_config_content(tmp_path):
    from gyroemu.dynamics.config import config_dir

    scenario = tmp_path / "sc.toml"
    text = (config_dir() / "scenarios" / "smooth_manoeuvre.toml").read_text()
    scenario.write_text(text)
    spec = _write(tmp_path / "c.toml", TINY.replace('["smooth_manoeuvre"]', '["sc.toml"]'))
    before = load_campaign(spec)
    assert before.cells[0].scenario == str(scenario.resolve())  # relative to the campaign file
    scenario.write_text(text + "\n# a comment changes no value\n")
    assert load_campaign(spec).tasks[0].key == before.tasks[0].key  # hashed as resolved, not as text
    assert "\nseed = 0\n" in text
    scenario.write_text(text.replace("\nseed = 0\n", "\nseed = 1\n"))  # another manoeuvre: other rows
    assert load_campaign(spec).tasks[0].key != before.tasks[0].key


@pytest.mark.parametrize(
    "edit, key",
    [
        ("\nseed_rnage = { start = 0, count = 2 }\n", "seed_rnage"),
        ("\nthreshold_deg = -1.0\n", "threshold_deg"),
        ("\nseeds = [1, 2]\n", None),  # with seed_range: one or the other
        ('\nbatched = "yes"\n', "batched"),  # a string is no boolean (it was taken as true)
    ],
)
def test_bad_keys_name_the_file_and_key(tmp_path, edit, key):
    spec = _write(tmp_path / "c.toml", TINY + edit)
    with pytest.raises(ConfigError) as info:
        load_campaign(spec)
    assert info.value.file == str(spec)
    if key is not None:
        assert info.value.key == key


@pytest.mark.parametrize(
    "old, new, key",
    [
        ('"smooth_manoeuvre"', '"smooth_manouevre"', "scenarios[0]"),
        ('"tactical_mems"', '"tactical_mem"', "devices[1]"),
        ('"mahony"', '"mahoney"', "filters[1]"),
    ],
)
def test_unknown_names_are_named_before_any_work(tmp_path, old, new, key):
    spec = _write(tmp_path / "c.toml", TINY.replace(old, new))
    with pytest.raises(ConfigError) as info:
        load_campaign(spec)
    assert (info.value.file, info.value.key) == (str(spec), key)
    assert new.strip('"') in str(info.value)


def test_cli_bad_campaign_exits_2_before_any_work(tmp_path, capsys):
    spec = _write(tmp_path / "c.toml", TINY + "\nbogus = 1\n")
    out = tmp_path / "out"
    assert cli.main(["bench", "--campaign", str(spec), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert str(spec) in err and "bogus" in err
    assert not out.exists()
    good = _write(tmp_path / "g.toml", TINY)
    with pytest.raises(SystemExit) as info:  # the grid is the file's
        cli.main(["bench", "--campaign", str(good), "--filter", "mekf", "--out", str(out)])
    assert info.value.code == 2
    # --scheduler with today's flags: checked as a campaign would be, before connecting to anything.
    for flags, named in ((["--scenario", "smooth_manouevre"], "--scenario"), (["--runs", "0"], "--runs")):
        with pytest.raises(SystemExit) as info:
            cli.main(["bench", "--scheduler", "tcp://127.0.0.1:1", *flags, "--out", str(out)])
        assert info.value.code == 2
        assert f"argument {named}" in capsys.readouterr().err
    assert not out.exists()


def test_a_duration_too_short_to_sample_is_refused_with_the_file(tmp_path):
    """A duration of one truth sample (smooth_manoeuvre's truth at 200 Hz) or of fewer than two of a
    device's samples: refused naming the file and the key, before any work (every task's worker failed
    with a traceback naming an --duration generate does not have, and left an empty index)."""
    for durations, devices, reason in (
        ("[0.5, 0.001]", '["consumer_mems"]', "0.001 s of smooth_manoeuvre at its 200 Hz is one truth sample"),
        ("[0.015]", '["free_gyro"]', "0.015 s is shorter than two samples of device free_gyro (0.02 s at 100 Hz)"),
    ):
        text = TINY.replace("[0.5]", durations).replace('["consumer_mems", "tactical_mems"]', devices)
        spec = _write(tmp_path / "c.toml", text)
        with pytest.raises(ConfigError) as info:
            load_campaign(spec)
        assert info.value.file == str(spec) and info.value.key.startswith("durations_s[")
        assert reason in str(info.value), str(info.value)


def test_durations_are_bounded_as_simulate_bounds_them(tmp_path):
    """A duration simulate refuses (> 1e7 s) is refused with the file, before any work (not per task)."""
    spec = _write(tmp_path / "c.toml", TINY.replace("[0.5]", "[0.5, 1e9]"))
    with pytest.raises(ConfigError) as info:
        load_campaign(spec)
    assert (info.value.file, info.value.key) == (str(spec), "durations_s[1]")
    assert "1e+09 is more than the limit of 1e+07" in str(info.value)
    out = tmp_path / "data"
    assert cli.main(["generate", str(spec), "--out-dir", str(out)]) == 2
    assert not out.exists()


@pytest.mark.parametrize("flags", [["--duration", "7"], ["--seed", "5"], ["--runs", "4"], ["--threshold-deg", "9"]])
def test_cli_campaign_refuses_the_numbers_of_todays_flags(tmp_path, capsys, flags):
    """The campaign file sets durations, seeds and threshold: the flags are refused, not ignored."""
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as info:
        cli.main(["bench", "--campaign", str(_write(tmp_path / "c.toml", TINY)), *flags, "--out", str(out)])
    assert info.value.code == 2
    assert f"the campaign file sets the grid; drop {flags[0]}" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize("command", ["bench", "generate"])
def test_a_bad_scheduler_address_is_refused_before_any_work(tmp_path, capsys, command):
    spec = _write(tmp_path / "c.toml", TINY)
    out = tmp_path / "out"
    argv = ["bench", "--runs", "1"] if command == "bench" else ["generate", str(spec)]
    argv += ["--out" if command == "bench" else "--out-dir", str(out), "--scheduler", "nonsense"]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert "argument --scheduler: 'nonsense' is not a scheduler address like tcp://HOST:8786" in err, err
    assert not out.exists()


@pytest.mark.parametrize("command", ["bench", "generate"])
def test_a_read_only_out_folder_is_refused_before_any_work(tmp_path, monkeypatch, capsys, command):
    """A read-only mount refuses even root, which a test cannot make: folder_problem is told so. The
    output folder (made when missing) is refused naming the option, not as an OSError later."""
    import gyroemu.pipelines.formats.atomic as atomic

    locked = tmp_path / "ro"
    locked.mkdir()
    real = atomic.folder_problem
    monkeypatch.setattr(atomic, "folder_problem", lambda f: "read-only file system" if f == locked else real(f))
    spec = _write(tmp_path / "c.toml", TINY)
    named = "--out" if command == "bench" else "--out-dir"
    argv = ["bench", "--campaign", str(spec)] if command == "bench" else ["generate", str(spec)]
    assert cli.main([*argv, named, str(locked / "made")]) == 2
    assert f"argument {named}: {locked}: read-only file system" in capsys.readouterr().err
    assert list(locked.iterdir()) == []


def test_a_campaign_overwrites_a_report_not_its_own_only_with_force(tmp_path, capsys):
    """bench.md there without a campaign's runs/ store is someone else's (a plain bench's, a user's)."""
    from gyroemu.pipelines.jobs.campaign import CampaignError, CampaignOptions, check_options

    out = tmp_path / "out"
    out.mkdir()
    (out / "bench.md").write_text("someone's notes")
    spec = _write(tmp_path / "c.toml", TINY)
    assert cli.main(["bench", "--campaign", str(spec), "--out", str(out)]) == 2
    assert f"argument --out: {out} holds bench.md" in capsys.readouterr().err
    assert [p.name for p in out.iterdir()] == ["bench.md"] and (out / "bench.md").read_text() == "someone's notes"
    check_options(CampaignOptions(spec=spec, out=out, force=True))
    (out / "runs").mkdir()  # the campaign's own report, rewritten as it resumes
    check_options(CampaignOptions(spec=spec, out=out))
    with pytest.raises(CampaignError, match="argument --scheduler"):
        check_options(CampaignOptions(spec=spec, out=out, scheduler="tcp://host"))


def test_a_campaign_never_writes_over_its_own_files_even_with_force(tmp_path, capsys):
    """The campaign file, or a device file it names, under a report file's name in --out: refused before
    any work, even with --force (bench --campaign wrote its report over the campaign file)."""
    from gyroemu.dynamics.config import config_dir
    from gyroemu.pipelines.jobs.campaign import CampaignError, CampaignOptions, check_options

    out = tmp_path / "out"
    out.mkdir()
    spec = _write(out / "bench.md", TINY)
    assert cli.main(["bench", "--campaign", str(spec), "--out", str(out), "--force"]) == 2
    assert f"argument --out: {spec} is an input: inputs are never overwritten, even with --force" in (
        capsys.readouterr().err
    )
    assert spec.read_text() == TINY and [p.name for p in out.iterdir()] == ["bench.md"]
    device = out / "bench.json"
    device.write_text((config_dir() / "devices" / "consumer_mems.toml").read_text())
    other = _write(tmp_path / "c.toml", TINY.replace('"consumer_mems"', f'"{device}"'))
    with pytest.raises(CampaignError, match="bench.json is an input"):
        check_options(CampaignOptions(spec=other, out=out, force=True), load_campaign(other))


LOG = "smooth_manoeuvre__consumer_mems__0.5s__seed0.mcap"


def test_generate_replaces_no_file_it_did_not_write(tmp_path, capsys):
    """A file at a log's path is kept only when it is that log (its gyroemu metadata: scenario and device
    configs, seed); anything else there, and an index generate did not write, is refused before any work
    naming the file, which stays as it was."""
    from gyroemu.pipelines.jobs.generate import (
        INDEX_COLUMNS,
        GenerateError,
        GenerateOptions,
        check_options,
        log_tasks,
    )

    spec = _write(tmp_path / "c.toml", 'scenarios = ["smooth_manoeuvre"]\ndevices = ["consumer_mems"]\n')
    spec.write_text(spec.read_text() + "durations_s = [0.5]\nseeds = [0]\n")
    out = tmp_path / "data"
    out.mkdir()
    log = out / LOG
    log.write_text("someone's notes")
    assert cli.main(["generate", str(spec), "--out-dir", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"argument --out-dir: {log} is not this campaign's log (not an MCAP file)" in err, err
    assert [p.name for p in out.iterdir()] == [LOG] and log.read_text() == "someone's notes"

    options = GenerateOptions(spec=spec, out_dir=out)
    tasks = log_tasks(load_campaign(spec), out)
    argv = ["--scenario", "smooth_manoeuvre", "--device", "consumer_mems", "--duration", "0.5", "--out", str(log)]
    assert cli.main(["simulate", *argv, "--seed", "1", "--force"]) == 0
    with pytest.raises(GenerateError, match="the log of seed 1, not 0"):
        check_options(options, tasks)
    assert cli.main(["simulate", *argv, "--seed", "0", "--force"]) == 0
    check_options(options, tasks)  # the task's own log: kept (or made again, the same bytes)

    (out / "index.csv").write_text("my,own,index\n")
    assert cli.main(["generate", str(spec), "--out-dir", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"argument --out-dir: {out / 'index.csv'} is not an index 'gyroemu generate' wrote" in err, err
    assert (out / "index.csv").read_text() == "my,own,index\n"
    (out / "index.csv").write_text(",".join(f'"{c}"' for c in INDEX_COLUMNS) + "\n")  # generate's own
    check_options(options, tasks)


def test_bench_flags_make_the_same_tasks_as_a_file(tmp_path):
    from gyroemu.pipelines.campaign import campaign_from_spec
    from gyroemu.pipelines.jobs.campaign import spec_from_bench_flags

    flags = spec_from_bench_flags(
        ["smooth_manoeuvre"],
        ["consumer_mems"],
        duration=0.5,
        runs=3,
        seed=7,
        filters=["madgwick", "mahony"],
        six_d=True,
        batched=True,
    )
    text = TINY.replace(', "tactical_mems"', "").replace('["9D", "6D"]', '["6D"]').replace("= 2\n", "= 25\n")
    from_file = load_campaign(_write(tmp_path / "c.toml", text))
    assert [t.key for t in campaign_from_spec(flags).tasks] == [t.key for t in from_file.tasks]
    assert len(from_file.tasks) == 1  # the store of one resumes the other


# --- the store and the engine -------------------------------------------------------------------------


def test_store_parts_are_whole_and_keyed(tmp_path):
    schema = pa.schema([("k", pa.string()), ("x", pa.float64())])
    store = PartStore(tmp_path / "runs", schema)
    assert store.keys() == set() and store.read().num_rows == 0
    store.write("a", [{"k": "a", "x": 1.0}, {"k": "a", "x": 2.0}])
    store.write("b", [{"k": "b", "x": 3.0}])
    (tmp_path / "runs" / ".part-c.parquet.x1y2.tmp").write_bytes(b"half a file")  # a write cut short
    assert store.keys() == {"a", "b"}
    assert store.read(["b", "missing"]).to_pylist() == [{"k": "b", "x": 3.0}]
    import pyarrow.dataset as ds

    assert sorted(ds.dataset(tmp_path / "runs").to_table()["x"].to_pylist()) == [1.0, 2.0, 3.0]


def _square_or_fail(task: int) -> list[dict]:
    if task == 3:
        raise ValueError("cell 3 is bad")
    return [{"task": task, "value": float(task * task)}]


def test_engine_reports_a_failing_task_and_stores_the_rest(tmp_path):
    store = PartStore(tmp_path, pa.schema([("task", pa.int64()), ("value", pa.float64())]))
    seen = []

    def stored(task, rows):
        seen.append(task)
        store.write(str(task), rows)

    failures = run_tasks(list(range(6)), _square_or_fail, stored, workers=2, processes=False)
    assert [(f.task, f.error) for f in failures] == [(3, "ValueError: cell 3 is bad")]
    assert sorted(seen) == [0, 1, 2, 4, 5]
    assert sorted(store.read()["value"].to_pylist()) == [0.0, 1.0, 4.0, 16.0, 25.0]


# --- a tiny campaign, in-process ----------------------------------------------------------------------


def test_tiny_campaign_rows_resume_and_report(tmp_path):
    import json

    from gyroemu.pipelines.jobs.bench import SimCase, run_bench
    from gyroemu.pipelines.jobs.campaign import CampaignOptions, run_campaign

    spec = _write(tmp_path / "c.toml", TINY)
    options = CampaignOptions(spec=spec, out=tmp_path / "out", workers=2, processes=False, plots=False)
    first = run_campaign(options)
    assert (first.ran, first.resumed, first.failures, first.rows) == (6, 0, [], 18)
    drawn = first.report  # the report is drawn from the store
    rows = PartStore(tmp_path / "out" / "runs", row_schema()).read().to_pylist()
    ident = [(r["task"], r["seed"], r["filter"]) for r in rows]
    assert len(ident) == len(set(ident)) == 18
    assert {(r["device"], r["mode"]) for r in rows} == {
        ("consumer_mems", "9D"),
        ("consumer_mems", "6D"),
        ("tactical_mems", "6D"),
    }

    # Each row is the bench's number for its cell and seed, to the bit.
    ref = run_bench([SimCase(device="tactical_mems", duration=0.5, six_d=True)], ["madgwick", "mahony"], 1, 9)
    got = {r["filter"]: r for r in rows if r["device"] == "tactical_mems" and r["seed"] == 9}
    for fr in ref.cases[0].filters:
        assert got[fr.filter]["inclination_deg"] == fr.runs[0].inclination_deg
        assert got[fr.filter]["total_deg"] is None  # 6D: no heading, no total

    report = json.loads((tmp_path / "out" / "bench.json").read_text())
    assert report["settings"]["campaign"]["rows_stored"] == 18
    assert sum(len(fr["runs"]) for case in report["cases"] for fr in case["filters"]) == 18
    assert len(drawn.cases) == 3

    # Resume: remove one part; only that task runs again, and the rows are the same.
    victim = next((tmp_path / "out" / "runs").glob("part-*.parquet"))
    victim.unlink()
    again = run_campaign(options)
    assert (again.ran, again.resumed, again.rows) == (1, 5, 18)
    after = PartStore(tmp_path / "out" / "runs", row_schema()).read().to_pylist()

    def numbers(rs):
        keep = ("task", "seed", "filter", "total_deg", "heading_deg", "inclination_deg", "convergence_s")
        return sorted(
            tuple(-1.0 if r[k] is None or (isinstance(r[k], float) and math.isnan(r[k])) else r[k] for k in keep)
            for r in rs
        )

    assert numbers(after) == numbers(rows)


def test_progress_counts_stored_runs_as_done_and_hides_off_a_terminal():
    import io

    from gyroemu.pipelines.campaign import RunsProgress

    stream = io.StringIO()
    with RunsProgress(24, 20, label="campaign x", stream=stream, enabled=True) as bar:
        bar.advance(4)
        bar.bar.refresh()
    assert "20/24" in stream.getvalue() and "24/24" in stream.getvalue() and "runs/s" in stream.getvalue()
    quiet = io.StringIO()  # not a terminal: no bar at all
    with RunsProgress(24, stream=quiet) as bar:
        assert bar.bar is None
        bar.advance(24)
    assert quiet.getvalue() == ""


def test_a_plain_bench_refuses_workers_it_would_ignore(tmp_path, capsys, monkeypatch):
    """``--workers`` sizes the local Dask cluster of ``--campaign``; a plain bench runs in its own process,
    so the option is refused (it was ignored), before any work."""
    from gyroemu.pipelines.jobs import bench

    def no_work(*args, **kwargs):
        raise AssertionError("the bench ran")

    monkeypatch.setattr(bench, "run_bench", no_work)
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as info:
        cli.main(["bench", "--runs", "1", "--duration", "2", "--workers", "2", "--out", str(out)])
    assert info.value.code == 2
    assert "argument --workers" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize(
    "address, problem",
    [
        ("tcp://127.0.0.1:8786", None),
        ("127.0.0.1:8786", None),
        ("[::1]:8786", None),
        ("tls://host:8786", None),
        ("ws://127.0.0.1:8799", None),  # Dask's other backends: taken as they are (a review, 2026-11-27)
        ("wss://host:443", None),
        ("ucx://host:13337", None),
        ("inproc://192.168.1.2/123/4", None),
        ("nonsense", "is not a scheduler address"),
        ("ftp://host:21", "no Dask protocol ftp://"),
        ("tcp://host:0", "the port must be 1 to 65535"),
        ("tcp://host", "is not a scheduler address"),
    ],
)
def test_scheduler_addresses_of_every_dask_protocol_are_taken(address, problem):
    from gyroemu.pipelines.campaign import scheduler_problem

    found = scheduler_problem(address)
    assert (found is None) if problem is None else (found is not None and problem in found), found


@pytest.mark.parametrize("n", [1, 3])
def test_a_full_disk_leaves_the_earlier_campaign_report_as_it_was(tmp_path, monkeypatch, n):
    """The report (bench.json, bench.md, a box plot per cell) is written all or none: a full disk at any
    of its files leaves the earlier report whole and no temporary file (the run store is not touched)."""
    import errno

    from full_disk import contents, disk_full_at

    from gyroemu.pipelines.jobs.bench import SimCase, run_bench
    from gyroemu.pipelines.jobs.campaign import save_campaign_report

    report = run_bench([SimCase("smooth_manoeuvre", "consumer_mems", duration=0.5)], filters=["madgwick"], runs=2)
    report.settings["campaign"] = {
        "name": "tiny",
        "store": "runs",
        "cells": 1,
        "seeds": [0, 1],
        "tasks": 1,
        "rows_expected": 2,
        "rows_stored": 2,
        "failures": [],
    }
    out = tmp_path / "out"
    (out / "runs").mkdir(parents=True)
    earlier = save_campaign_report(report, None, out)
    assert len(earlier["plots"]) == 1
    before = contents(out)
    report.settings["campaign"]["name"] = "again"
    asked = disk_full_at(monkeypatch, n)
    with pytest.raises(OSError) as caught:
        save_campaign_report(report, None, out)
    assert caught.value.errno == errno.ENOSPC and len(asked) == n
    assert contents(out) == before


# --- faults: the store's own errors, bad grids, another campaign's folder, damaged parts ----------------

ONE = """
name = "one"
scenarios = ["smooth_manoeuvre"]
devices = ["consumer_mems"]
durations_s = [0.5]
seed_range = { start = 0, count = 2 }
filters = ["madgwick"]
seeds_per_task = 1
"""


def _in_process(spec: Path, out: Path, **kwargs):
    from gyroemu.pipelines.jobs.campaign import CampaignOptions

    return CampaignOptions(spec=spec, out=out, workers=1, processes=False, plots=False, **kwargs)


def _stored(out: Path) -> list[tuple]:
    """(campaign, seed, filter) of every row ``out/runs`` reads as (pyarrow.dataset, as README reads it)."""
    import pyarrow.dataset as ds

    rows = ds.dataset(out / "runs").to_table().to_pylist()
    return sorted((r["campaign"], r["seed"], r["filter"]) for r in rows)


@pytest.fixture
def no_work(monkeypatch):
    """Any task submitted fails the test: what is refused must be refused before the work."""
    import gyroemu.pipelines.campaign as campaign

    def run_tasks(*args, **kwargs):
        raise AssertionError("the work ran")

    monkeypatch.setattr(campaign, "run_tasks", run_tasks)


def test_an_error_storing_a_result_is_no_lost_scheduler(tmp_path):
    """An error of the callback that stores a task's result (a full disk) goes through as it is: it was
    reported as 'lost the Dask scheduler (OSError: No space left on device)'."""
    import errno

    from gyroemu.pipelines.campaign import SchedulerLostError

    def full(task, rows):
        raise OSError(errno.ENOSPC, "No space left on device")

    with pytest.raises(OSError) as info:
        run_tasks(list(range(3)), _square_or_fail, full, workers=1, processes=False)
    assert info.value.errno == errno.ENOSPC and not isinstance(info.value, SchedulerLostError)


def test_a_full_disk_storing_a_part_stops_the_campaign_with_the_disk_error(tmp_path, monkeypatch):
    import errno

    from full_disk import disk_full_at

    from gyroemu.pipelines.jobs.campaign import run_campaign

    spec = _write(tmp_path / "c.toml", ONE)
    disk_full_at(monkeypatch, 1)  # the first part
    with pytest.raises(OSError) as info:
        run_campaign(_in_process(spec, tmp_path / "out"))
    assert info.value.errno == errno.ENOSPC
    assert not list((tmp_path / "out" / "runs").iterdir())  # no part, no temporary file


def test_a_file_named_runs_in_out_is_refused_before_any_work(tmp_path, capsys, no_work):
    from gyroemu.pipelines.jobs.campaign import CampaignError, check_options

    spec = _write(tmp_path / "c.toml", ONE)
    out = tmp_path / "out"
    out.mkdir()
    (out / "runs").write_text("my notes")
    assert cli.main(["bench", "--campaign", str(spec), "--out", str(out)]) == 2
    assert f"argument --out: {out / 'runs'} is not a folder" in capsys.readouterr().err
    assert (out / "runs").read_text() == "my notes" and [p.name for p in out.iterdir()] == ["runs"]
    with pytest.raises(CampaignError, match="argument --out"):  # --force overwrites reports, not this
        check_options(_in_process(spec, out, force=True))


def test_a_seed_range_past_int64_is_refused_before_any_work(tmp_path, capsys, no_work):
    spec = _write(tmp_path / "c.toml", ONE.replace("start = 0, count = 2", f"start = {2**63 - 2}, count = 4"))
    with pytest.raises(ConfigError) as info:
        load_campaign(spec)
    assert (info.value.file, info.value.key) == (str(spec), "seed_range") and str(2**63 + 1) in str(info.value)
    # its last seed 2**63 - 1: taken
    load_campaign(_write(tmp_path / "d.toml", ONE.replace("start = 0, count = 2", f"start = {2**63 - 4}, count = 4")))
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as exit_info:  # bench's flags as a campaign: the argument named
        cli.main(
            ["bench", "--scheduler", "tcp://127.0.0.1:1", "--seed", str(2**63 - 2), "--runs", "4", "--out", str(out)]
        )
    assert exit_info.value.code == 2
    assert "argument --seed: --seed 9223372036854775806 + --runs 4" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize("key", ["devices", "scenarios"])
def test_one_config_under_two_names_is_refused_naming_both_entries(tmp_path, key):
    """A built-in by name and by its file's path are one config: two cells of one task key (one of them
    never stored, the campaign never complete). Refused, naming both entries; the same name twice is
    one entry, as before."""
    from gyroemu.dynamics.config import config_dir

    kind, name = {"devices": ("devices", "consumer_mems"), "scenarios": ("scenarios", "smooth_manoeuvre")}[key]
    path = config_dir() / kind / f"{name}.toml"
    spec = _write(tmp_path / "c.toml", ONE.replace(f'["{name}"]', f'["{name}", "{path}"]'))
    with pytest.raises(ConfigError) as info:
        load_campaign(spec)
    assert (info.value.file, info.value.key) == (str(spec), f"{key}[1]")
    assert f"{key}[0] ('{name}')" in str(info.value) and "same config" in str(info.value)
    twice = load_campaign(_write(tmp_path / "d.toml", ONE.replace(f'["{name}"]', f'["{name}", "{name}"]')))
    assert len(twice.cells) == 1


def test_another_campaign_in_out_is_refused_and_force_moves_its_results_aside(tmp_path, capsys):
    """Another campaign (name or file) in --out: refused before any work naming what differs (it replaced
    the report and piled its rows into runs/); with --force its report and parts go to
    out/superseded/<time>/, and runs/ reads as this campaign's rows alone."""
    import json

    from gyroemu.pipelines.jobs.campaign import SUPERSEDED, CampaignError, check_options, run_campaign

    out = tmp_path / "out"
    first = _write(tmp_path / "one.toml", ONE)
    run_campaign(_in_process(first, out))
    before = {p.name: p.read_bytes() for p in (out / "runs").iterdir()}
    other = _write(tmp_path / "two.toml", ONE.replace('"one"', '"two"').replace("count = 2", "count = 1"))
    assert cli.main(["bench", "--campaign", str(other), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"argument --out: {out} holds the results of another campaign" in err
    assert "campaign 'one', not 'two'" in err and f"from {first}, not {other}" in err
    assert {p.name: p.read_bytes() for p in (out / "runs").iterdir()} == before
    # the same name in another file is another campaign too
    same_name = _write(tmp_path / "elsewhere.toml", ONE)
    with pytest.raises(CampaignError, match=f"from {first}, not {same_name}"):
        check_options(_in_process(same_name, out), load_campaign(same_name))

    summary = run_campaign(_in_process(other, out, force=True))
    assert summary.superseded is not None and summary.superseded.parent == out / SUPERSEDED
    assert _stored(out) == [("two", 0, "madgwick")]
    assert {p.name: p.read_bytes() for p in (summary.superseded / "runs").iterdir()} == before
    assert json.loads((summary.superseded / "bench.json").read_text())["settings"]["campaign"]["name"] == "one"
    report = json.loads((out / "bench.json").read_text())["settings"]["campaign"]
    assert (report["name"], report["rows_stored"]) == ("two", 1)
    again = run_campaign(_in_process(other, out))  # now its own: resumed, nothing moved
    assert (again.ran, again.resumed, again.superseded) == (0, 1, None)


def test_an_edited_campaign_resumes_and_its_old_parts_leave_runs(tmp_path):
    """The same campaign file edited (seeds_per_task) is the same campaign: resumed without --force, and
    the parts of tasks it no longer has are moved aside, so runs/ reads each run once (twice before)."""
    from gyroemu.pipelines.jobs.campaign import run_campaign

    out = tmp_path / "out"
    spec = _write(tmp_path / "c.toml", ONE)
    run_campaign(_in_process(spec, out))
    spec.write_text(ONE.replace("seeds_per_task = 1", "seeds_per_task = 2"))
    summary = run_campaign(_in_process(spec, out))
    assert (summary.ran, summary.resumed, summary.rows) == (1, 0, 2)
    assert _stored(out) == [("one", 0, "madgwick"), ("one", 1, "madgwick")]
    assert len(list((summary.superseded / "runs").iterdir())) == 2 and not (summary.superseded / "bench.json").exists()


def test_the_same_campaign_run_from_another_folder_is_its_own(tmp_path, monkeypatch):
    """The report names the campaign file as given (relative): from another folder it is still the same
    campaign (its relative store tells the folder the earlier run started in)."""
    import json

    from gyroemu.pipelines.jobs.campaign import other_campaign

    out = tmp_path / "work" / "out"
    (out / "runs").mkdir(parents=True)
    spec = _write(tmp_path / "work" / "c.toml", ONE)
    report = {"gyroemu_bench": 1, "settings": {"campaign": {"name": "one", "file": "c.toml", "store": "out/runs"}}}
    (out / "bench.json").write_text(json.dumps(report))
    monkeypatch.chdir(tmp_path)
    assert other_campaign(out, load_campaign(spec)) is None
    assert other_campaign(Path("work/out"), load_campaign(Path("work/c.toml"))) is None
    (tmp_path / "work" / "d.toml").write_text(ONE)
    assert "from c.toml, not" in other_campaign(out, load_campaign(tmp_path / "work" / "d.toml"))


def test_a_batched_campaign_says_how_many_runs_a_task_ran_at_once(tmp_path):
    """The batched mekf runs each task's seeds at once (here 1), not all the case's (3): bench's '(3 runs
    at once)' and its JSON definition were wrong for a campaign. (The report of hand-made rows: the
    words are the report's, whatever the numbers.)"""
    import json

    from gyroemu.pipelines.jobs.campaign import BATCHED_THROUGHPUT, campaign_report, save_campaign_report

    def hand_made(campaign):
        rows = [
            {"task": t.key, "seed": seed, "filter": f, "filter_name": f, "batched": f == "mekf", "case": "c"}
            | {"mode": "9D", "rate_hz": 100.0, "samples": 50, "total_deg": 1.0, "throughput": 1e5, "wall_s": 0.1}
            | {"diverged": False}
            for t in campaign.tasks
            for seed in t.seeds
            for f in campaign.filters
        ]
        return pa.Table.from_pylist(rows, schema=row_schema())

    text = ONE.replace('["madgwick"]', '["mekf", "madgwick"]').replace("count = 2", "count = 3")
    campaign = load_campaign(_write(tmp_path / "c.toml", text + "batched = true\n"))
    table = hand_made(campaign)
    save_campaign_report(campaign_report(campaign, table), table, tmp_path, plots=False)
    md = (tmp_path / "bench.md").read_text()
    row = next(line for line in md.splitlines() if "mekf [batched]" in line)
    assert "(1 run at once)" in row and "(3 runs at once)" not in md
    assert "across the runs one task ran at once" in md and "across all runs at once" not in md
    data = json.loads((tmp_path / "bench.json").read_text())
    assert BATCHED_THROUGHPUT in data["definitions"]["throughput"]
    assert data["cases"][0]["source"]["runs_at_once"] == [1]
    # without a batched row: bench's words, as before
    campaign = load_campaign(_write(tmp_path / "d.toml", text.replace('"mekf", ', "")))
    table = hand_made(campaign)
    out = tmp_path / "plain"
    save_campaign_report(campaign_report(campaign, table), table, out, plots=False)
    assert "across all runs at once" in (out / "bench.md").read_text()
    assert "runs_at_once" not in json.loads((out / "bench.json").read_text())["cases"][0]["source"]


def test_generate_removes_its_own_stale_temporary_logs_and_no_other_file(tmp_path):
    """A generate killed mid-log leaves ``.<log>.<8 characters>.tmp``: the next run removes those of its
    logs (and index), never another file."""
    from gyroemu.pipelines.jobs.generate import GenerateOptions, run_generate

    spec = _write(tmp_path / "c.toml", ONE.replace("count = 2", "count = 1"))
    out = tmp_path / "data"
    out.mkdir()
    stale = [out / f".{LOG}.0a1b2c3d.tmp", out / ".index.parquet.x_9y8z7w.tmp"]
    kept = [out / ".other.mcap.0a1b2c3d.tmp", out / f".{LOG}.notes.tmp", out / f"{LOG}.0a1b2c3d.tmp"]
    for path in stale + kept:
        path.write_bytes(b"partial")
    summary = run_generate(GenerateOptions(spec=spec, out_dir=out, workers=1, processes=False))
    assert summary.made == 1 and (out / LOG).is_file()
    assert not any(p.exists() for p in stale) and all(p.read_bytes() == b"partial" for p in kept)


def test_parts_are_synced_before_and_after_their_rename(tmp_path, monkeypatch):
    """Without fsync a power loss can keep the rename and lose the data: an empty part."""
    import os

    from gyroemu.pipelines.formats import atomic

    synced: list[str] = []
    real = os.fsync

    def fsync(fd):
        synced.append(os.readlink(f"/proc/self/fd/{fd}") if os.path.exists("/proc/self/fd") else str(fd))
        real(fd)

    monkeypatch.setattr(atomic.os, "fsync", fsync)
    store = PartStore(tmp_path / "runs", pa.schema([("x", pa.float64())]))
    path = store.write("a", [{"x": 1.0}])
    assert len(synced) == 2
    if os.path.exists("/proc/self/fd"):
        assert synced[0].startswith(str(tmp_path / "runs" / ".part-a.parquet.")) and synced[1] == str(path.parent)


def test_an_empty_part_is_run_again_not_a_crash(tmp_path):
    """A part left empty (its rename on the disk before its data) made every resume crash (ArrowInvalid:
    Parquet file size is 0 bytes): it counts as missing, with a warning, and its task runs again."""
    from gyroemu.pipelines.campaign import StoreWarning
    from gyroemu.pipelines.jobs.campaign import run_campaign

    spec = _write(tmp_path / "c.toml", ONE)
    out = tmp_path / "out"
    run_campaign(_in_process(spec, out))
    victim = sorted((out / "runs").iterdir())[0]
    victim.write_bytes(b"")
    with pytest.warns(StoreWarning, match=f"{victim.name}: empty: its task runs again"):
        summary = run_campaign(_in_process(spec, out))
    assert (summary.ran, summary.resumed, summary.rows) == (1, 1, 2) and victim.stat().st_size > 0
    store = PartStore(out / "runs", row_schema())
    (out / "runs" / victim.name).write_bytes(b"PAR1" + b"\0" * 8 + b"PAR1")  # looks whole, reads not
    with pytest.warns(StoreWarning, match="cannot be read"):
        assert store.read().num_rows == 1


def test_log_names_keep_their_durations_and_tell_close_ones_apart(tmp_path):
    """A log's name says its duration as ':g' does where that is exact (every dataset so far keeps its
    names), else exactly: 3.000001 and 3.000002 made one name (and an error blaming the files' names)."""
    from gyroemu.pipelines.jobs.generate import duration_name, log_tasks

    for d in (0.5, 1.0, 3.0, 2.25, 0.1, 60.0, 1e6, 1e-3, 1234.5):
        assert duration_name(d) == f"{d:g}"
    assert (duration_name(3.000001), duration_name(3.000002)) == ("3.000001", "3.000002")
    assert duration_name(1234567.5) == "1234567.5"  # ':g' says 1.23457e+06
    spec = _write(tmp_path / "c.toml", ONE.replace("[0.5]", "[3.000001, 3.000002, 3.0]"))
    names = [Path(t.out).name for t in log_tasks(load_campaign(spec), tmp_path)]
    assert len(set(names)) == len(names) == 6
    assert "smooth_manoeuvre__consumer_mems__3.000001s__seed0.mcap" in names
    assert "smooth_manoeuvre__consumer_mems__3s__seed0.mcap" in names


def test_two_device_files_of_one_stem_are_named_with_their_key(tmp_path):
    from gyroemu.dynamics.config import config_dir
    from gyroemu.pipelines.jobs.generate import log_tasks

    text = (config_dir() / "devices" / "consumer_mems.toml").read_text()
    assert "\nrate_hz = 1000\n" in text
    for folder, rate in (("a", "1000"), ("b", "500")):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "imu.toml").write_text(text.replace("\nrate_hz = 1000\n", f"\nrate_hz = {rate}\n", 1))
    spec = _write(tmp_path / "c.toml", ONE.replace('["consumer_mems"]', '["a/imu.toml", "b/imu.toml"]'))
    with pytest.raises(ConfigError) as info:
        log_tasks(load_campaign(spec), tmp_path)
    assert info.value.key == "devices" and "give device files distinct names" in str(info.value)


def _slow_first(task: int) -> list[dict]:
    if task == 0:
        time.sleep(0.5)
    return [{"task": task, "value": float(task)}]


def test_a_result_lost_with_its_worker_is_awaited_again(monkeypatch):
    """A future ``as_completed`` hands over whose worker then dies reads "lost" (or "pending", being
    computed again), not "finished": it was reported as 'lost the Dask scheduler' with the scheduler
    alive (CI: a worker killed mid-campaign). Here ``as_completed`` hands over the first, slow task
    before it finishes, as it stands after its worker's death."""
    import distributed

    real = distributed.as_completed

    class EarlyFirst:
        def __init__(self, futures):
            self.first, self.rest = futures[0], real(futures[1:])

        def __iter__(self):
            return self

        def __next__(self):
            if self.first is not None:
                first, self.first = self.first, None
                assert first.status == "pending"
                return first
            return next(self.rest)

        def add(self, future):
            self.rest.add(future)

    monkeypatch.setattr(distributed, "as_completed", EarlyFirst)
    seen = {}
    failures = run_tasks(
        list(range(3)), _slow_first, lambda task, rows: seen.update({task: rows}), workers=1, processes=False
    )
    assert failures == []
    assert seen == {t: [{"task": t, "value": float(t)}] for t in range(3)}


def test_a_result_cancelled_as_it_is_fetched_is_a_lost_scheduler(monkeypatch):
    """The client cancels every future when it loses the scheduler; one that had finished when
    ``as_completed`` handed it over raises ``FutureCancelledError`` (a ``concurrent.futures.CancelledError``) as its
    result is fetched: that is the lost scheduler, said as such (it went out as a traceback, exit 1)."""
    import distributed
    from distributed.client import FutureCancelledError

    from gyroemu.pipelines.campaign import SchedulerLostError

    real = distributed.as_completed

    def cancelled_on_fetch(futures):
        for future in real(futures):
            key = future.key

            def result(timeout=None):
                raise FutureCancelledError(key, "scheduler-connection-lost", "Client lost the connection")

            future.result = result
            yield future

    monkeypatch.setattr(distributed, "as_completed", cancelled_on_fetch)
    seen = []
    with pytest.raises(
        SchedulerLostError, match=r"^lost the Dask scheduler \(the local cluster\) with 0 of 2 tasks finished$"
    ):
        run_tasks([1, 2], _slow_first, lambda task, rows: seen.append(task), workers=1, processes=False)
    assert seen == []

"""Mutation testing of gyroemu's physics and codec cores with cosmic-ray.

    python tests/mutation/run_mutation.py                 # a seeded sample per module (about 30 min)
    python tests/mutation/run_mutation.py --full          # every mutant (hours: run it in the background)
    python tests/mutation/run_mutation.py --module sensors/fog.py --per-module 40 --seed 3

Needs the ``mutation`` extra (``pip install -e '.[test,mutation]'``). Outside CI.

How it works. cosmic-ray (a well-kept mutation tool that edits the source file on disk, runs a test
command, and restores the file) mutates one module at a time: every arithmetic, comparison, boolean,
unary and constant operator it knows, one occurrence per mutant. Each mutant runs only the tests of
its module (``MODULES`` below), with ``pytest -x`` on one process, and is *killed* when they fail or
time out, *survives* when they pass.

The work happens in copies of the checkout, never in it: each of the ``--workers`` copies has its
own tree (``repo/``) and a package tree (``pkg/gyroemu``) whose subpackages are symbolic links into
that copy, put first on ``PYTHONPATH``, so the tests import the mutated copy and nothing else. Copies
keep modules apart: a mutant of ``rotation.py`` must not fail ``test_fog.py`` running beside it.

numba. gyroemu's compiled kernels are plain Python functions handed to numba on first call, and numba
keys its on-disk cache on the source file's time stamp: a mutated file is recompiled, so cosmic-ray's
source edits reach the compiled code. The report counts the mutants that sit inside ``@njit`` /
``@guvectorize`` functions, and how many of them were killed, to show it.

Sampling. ``--per-module K`` keeps a seeded random sample of K mutants per module (``--seed``), drawn
from the mutants ordered by what they are (place in the source, operator, occurrence; before
2026-11-26 by cosmic-ray's job ids, random UUIDs, so a seed did not name the same sample twice), and
marks the others skipped; ``--full`` runs them all. The report (stdout, and ``report.json`` in the
work folder) gives per module the mutant count, those run, killed, survived, and the score
killed / (killed + survived), with each survivor's diff for triage.
"""

from __future__ import annotations

import argparse
import ast
import concurrent.futures
import json
import os
import random
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

# module (path in the checkout) -> the tests that hold it
MODULES: dict[str, list[str]] = {
    "sensors/mechanism.py": ["tests/sensors/test_imu.py"],
    "sensors/errors.py": ["tests/sensors/test_errors.py", "tests/sensors/test_noise_density_convention.py"],
    "sensors/rate_gyro.py": ["tests/sensors/test_rate_gyro.py"],
    "sensors/rate_integrating.py": ["tests/sensors/test_rate_integrating.py"],
    "sensors/free_gyro.py": ["tests/sensors/test_free_gyro.py"],
    "sensors/mems.py": ["tests/sensors/test_mems.py"],
    "sensors/fog.py": ["tests/sensors/test_fog.py"],
    "sensors/rlg.py": ["tests/sensors/test_rlg.py"],
    "dynamics/rigid_body.py": ["tests/dynamics/test_rigid_body.py", "tests/dynamics/test_impact.py"],
    "dynamics/body_kernels.py": ["tests/dynamics/test_rigid_body.py", "tests/dynamics/test_impact.py"],
    "dynamics/rotation.py": ["tests/dynamics/test_rotation.py"],
    "dynamics/cubic.py": ["tests/dynamics/test_cubic.py"],
    "dynamics/attitude_fusion.py": ["tests/dynamics/test_attitude_fusion.py"],
    "dynamics/trajectory.py": [
        "tests/dynamics/test_earth.py",
        "tests/dynamics/test_motions.py",
        "tests/dynamics/test_scenarios.py",
    ],
    "dynamics/earth.py": ["tests/dynamics/test_earth.py"],
    "pipelines/estimation/mekf_kernels.py": ["tests/pipelines/test_mekf.py"],
    "pipelines/estimation/mekf_smoother_kernels.py": [
        "tests/pipelines/test_mekf_smoother.py",
        "tests/pipelines/test_smoother_spool.py",
    ],
    "pipelines/estimation/mekf_smoother.py": [
        "tests/pipelines/test_mekf_smoother.py",
        "tests/pipelines/test_smoother_spool.py",
    ],
    "pipelines/estimation/mekf_smoother_spool.py": ["tests/pipelines/test_smoother_spool.py"],
    "pipelines/estimation/latency.py": ["tests/pipelines/test_latency.py"],
    "pipelines/estimation/field_lag.py": ["tests/pipelines/test_field_lag.py"],
    "pipelines/formats/device_stream.py": [
        "tests/pipelines/test_estimate_stream.py",
        "tests/pipelines/test_bench_log.py",
    ],
    "pipelines/jobs/bench_metrics.py": ["tests/pipelines/test_bench_metrics.py"],
    "pipelines/identification/noise.py": ["tests/pipelines/test_identify.py"],
    "pipelines/identification/result.py": ["tests/pipelines/test_identify.py"],
    "pipelines/formats/messages.py": ["tests/pipelines/test_messages.py"],
    "pipelines/formats/channels.py": ["tests/pipelines/test_mcap_io.py"],
    "pipelines/formats/mcap_records.py": ["tests/pipelines/test_mcap_io.py"],
    "pipelines/formats/mcap_log.py": ["tests/pipelines/test_mcap_io.py"],
    "pipelines/twin/motion.py": ["tests/pipelines/test_twin.py", "tests/dynamics/test_attitude_fusion.py"],
    "pipelines/twin/recording.py": ["tests/pipelines/test_twin.py"],
    "pipelines/twin/residuals.py": ["tests/pipelines/test_twin.py"],
    "pipelines/twin/runs.py": ["tests/pipelines/test_twin.py"],
    "pipelines/twin/report.py": ["tests/pipelines/test_twin.py"],
    "pipelines/twin/site.py": ["tests/pipelines/test_twin.py"],
}


def make_copy(folder: Path) -> Path:
    """A copy of the checkout's tracked files in ``folder/repo`` and its package tree in ``folder/pkg``."""
    repo = folder / "repo"
    files = subprocess.run(
        ["git", "ls-files", "--cached", "--others", "--exclude-standard"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    for name in files.splitlines():
        target = repo / name
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / name, target)
    package = folder / "pkg" / "gyroemu"
    package.mkdir(parents=True)
    for item in (repo / "src" / "gyroemu").iterdir():
        (package / item.name).symlink_to(item)
    for sub in ("dynamics", "sensors", "pipelines", "configs"):
        (package / sub).symlink_to(repo / sub)
    return repo


def test_command(tests: list[str]) -> str:
    return shlex.join(
        [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", "-o", "addopts=", "-n", "0"]
        + ["--import-mode=importlib", "-m", "not slow", *tests]
    )


def compiled_ranges(path: Path) -> list[tuple[int, int]]:
    """(first line, last line) of each function compiled by numba (decorated with njit or guvectorize)."""
    ranges = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.FunctionDef):
            names = {ast.unparse(d).split("(")[0].split(".")[-1] for d in node.decorator_list}
            if names & {"njit", "guvectorize"}:
                ranges.append((node.lineno, node.end_lineno or node.lineno))
    return ranges


def annotation_spans(path: Path) -> list[tuple[tuple[int, int], tuple[int, int]]]:
    """((line, col), (end line, end col)) of every annotation: with ``from __future__ import annotations``
    they are strings that are never evaluated, so a mutant inside one is equivalent by construction."""
    spans = []
    for node in ast.walk(ast.parse(path.read_text())):
        annotations = []
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            args = node.args
            every = args.posonlyargs + args.args + args.kwonlyargs + [a for a in (args.vararg, args.kwarg) if a]
            annotations = [a.annotation for a in every if a.annotation] + ([node.returns] if node.returns else [])
        elif isinstance(node, ast.AnnAssign):
            annotations = [node.annotation]
        spans += [((a.lineno, a.col_offset), (a.end_lineno or a.lineno, a.end_col_offset or 0)) for a in annotations]
    return spans


def run_module(module: str, folder: Path, per_module: int | None, seed: int) -> dict:
    """Init, sample and execute one module's mutants in the copy at ``folder``; the module's summary."""
    from cosmic_ray.work_db import WorkDB, use_db
    from cosmic_ray.work_item import TestOutcome, WorkerOutcome, WorkResult

    repo = folder / "repo"
    env = {**os.environ, "PYTHONPATH": str(folder / "pkg"), "PYTHONDONTWRITEBYTECODE": "1"}
    command = test_command(MODULES[module])
    started = time.perf_counter()  # the unmutated run: the tests must pass, and it sets the timeout
    baseline = subprocess.run(shlex.split(command), cwd=repo, env=env, capture_output=True, text=True)
    if baseline.returncode != 0:
        raise RuntimeError(f"{module}: the unmutated tests fail:\n{baseline.stdout[-2000:]}")
    timeout = max(60.0, 4 * (time.perf_counter() - started))  # + a recompile of the module's kernels
    name = module.replace("/", "_").removesuffix(".py")
    config, session = folder / f"{name}.toml", folder / f"{name}.sqlite"
    config.write_text(
        "[cosmic-ray]\n"
        f'module-path = "{module}"\n'
        f"timeout = {timeout:.0f}\n"
        "excluded-modules = []\n"
        f"test-command = {json.dumps(command)}\n"
        '[cosmic-ray.distributor]\nname = "local"\n'
    )
    cosmic = [str(Path(sys.executable).with_name("cosmic-ray"))]
    subprocess.run([*cosmic, "init", str(config), str(session)], cwd=repo, env=env, check=True)
    future_annotations = "from __future__ import annotations" in (repo / module).read_text()
    spans = annotation_spans(repo / module) if future_annotations else []
    with use_db(str(session), WorkDB.Mode.open) as db:
        in_annotation = [
            item.job_id
            for item in db.pending_work_items
            if any(first <= tuple(item.mutations[0].start_pos) < last for first, last in spans)
        ]
        equivalent = WorkResult(output="in an annotation (never evaluated)", worker_outcome=WorkerOutcome.SKIPPED)
        db.set_multiple_results(in_annotation, equivalent)
        items = list(db.pending_work_items)
        ids = [item.job_id for item in items]
        if per_module is not None and per_module < len(ids):
            # Job ids are random UUIDs, new at every init: sample by what each mutant is (its place in
            # the source, its operator and occurrence), so that a seed names the same mutants every run.
            def identity(item) -> tuple:
                m = item.mutations[0]
                return (tuple(m.start_pos), tuple(m.end_pos), m.operator_name, m.occurrence)

            ordered = [item.job_id for item in sorted(items, key=identity)]
            keep = set(random.Random(f"{seed}:{module}").sample(ordered, per_module))
            skipped = WorkResult(output="not in the sample", worker_outcome=WorkerOutcome.SKIPPED)
            db.set_multiple_results([i for i in ids if i not in keep], skipped)
    subprocess.run([*cosmic, "exec", str(config), str(session)], cwd=repo, env=env, check=True)

    compiled = compiled_ranges(ROOT / module)
    summary = {
        "module": module,
        "mutants": len(ids) + len(in_annotation),
        "in_annotations": len(in_annotation),
        "timeout_s": round(timeout),
        "survivors": [],
    }
    counts = {"run": 0, "killed": 0, "survived": 0, "incompetent": 0, "compiled_run": 0, "compiled_killed": 0}
    with use_db(str(session), WorkDB.Mode.open) as db:
        for item, result in db.completed_work_items:
            if result.worker_outcome == WorkerOutcome.SKIPPED:
                continue
            counts["run"] += 1
            line = item.mutations[0].start_pos[0]
            in_compiled = any(first <= line <= last for first, last in compiled)
            counts["compiled_run"] += in_compiled
            if result.test_outcome == TestOutcome.KILLED:
                counts["killed"] += 1
                counts["compiled_killed"] += in_compiled
            elif result.test_outcome == TestOutcome.SURVIVED:
                counts["survived"] += 1
                summary["survivors"].append(
                    {"line": line, "operator": item.mutations[0].operator_name, "diff": result.diff}
                )
            else:
                counts["incompetent"] += 1
    summary.update(counts)
    decided = counts["killed"] + counts["survived"]
    summary["score"] = counts["killed"] / decided if decided else None
    return summary


def run_worker(modules: list[str], folder: Path, per_module: int | None, seed: int) -> list[dict]:
    make_copy(folder)
    return [run_module(m, folder, per_module, seed) for m in modules]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true", help="every mutant (hours), not a sample")
    parser.add_argument("--per-module", type=int, default=10, help="mutants sampled per module (default: 10)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the sample (default: 0)")
    parser.add_argument("--module", action="append", choices=sorted(MODULES), help="only these (repeatable)")
    parser.add_argument("--workers", type=int, default=2, help="copies run side by side (default: 2)")
    parser.add_argument("--workdir", type=Path, default=None, help="work folder (default: a new temporary one)")
    args = parser.parse_args()
    modules = args.module or list(MODULES)
    per_module = None if args.full else args.per_module
    workdir = args.workdir or Path(
        subprocess.run(["mktemp", "-d", "-t", "gyroemu-mutation.XXXX"], capture_output=True, text=True).stdout.strip()
    )
    workdir.mkdir(parents=True, exist_ok=True)
    shares = [modules[i :: args.workers] for i in range(args.workers)]
    started = time.perf_counter()
    with concurrent.futures.ProcessPoolExecutor(args.workers) as pool:
        futures = [
            pool.submit(run_worker, share, workdir / f"worker{i}", per_module, args.seed)
            for i, share in enumerate(shares)
            if share
        ]
        results = sorted((s for f in futures for s in f.result()), key=lambda s: modules.index(s["module"]))
    (workdir / "report.json").write_text(json.dumps(results, indent=1))

    print(
        f"\n{'module':<40} {'mutants':>7} {'annot.':>6} {'run':>5} {'killed':>6} {'survived':>8} {'other':>5} "
        f"{'score':>6}  compiled"
    )
    for s in results:
        score = "-" if s["score"] is None else f"{s['score']:.0%}"
        compiled = f"{s['compiled_killed']}/{s['compiled_run']} killed"
        print(
            f"{s['module']:<40} {s['mutants']:>7} {s['in_annotations']:>6} {s['run']:>5} {s['killed']:>6} "
            f"{s['survived']:>8} {s['incompetent']:>5} {score:>6}  {compiled}"
        )
    killed = sum(s["killed"] for s in results)
    survived = sum(s["survived"] for s in results)
    print(
        f"all: {sum(s['mutants'] for s in results)} mutants, {killed + survived} decided, "
        f"score {killed / max(1, killed + survived):.1%}, in {time.perf_counter() - started:.0f} s"
    )
    print(f"report and survivors' diffs: {workdir / 'report.json'}")


if __name__ == "__main__":
    main()

"""gyroemu as a package: one import root, a wheel that carries its configs, no side effects on import.

The wheel is built from this checkout without build isolation (setuptools from the test extras), so the
test needs no network. Imports are checked in fresh interpreters, where nothing else has loaded numba.
"""

import importlib
import json
import os
import subprocess
import sys
import zipfile
from importlib.metadata import entry_points, version
from pathlib import Path

import pytest

import gyroemu

ROOT = Path(__file__).resolve().parents[1]
SOURCE_FOLDERS = ("dynamics", "sensors", "pipelines", "configs")


def run_python(code: str) -> str:
    """stdout of ``code`` run in a fresh interpreter, away from the checkout (so only the install counts)."""
    done = subprocess.run(
        [sys.executable, "-P", "-c", code], capture_output=True, text=True, cwd=ROOT.parent, check=False
    )
    assert done.returncode == 0, done.stderr
    return done.stdout


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> zipfile.ZipFile:
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(out), str(ROOT)],
        check=True,
        capture_output=True,
    )
    (path,) = out.glob("gyroemu-*.whl")
    with zipfile.ZipFile(path) as archive:
        yield archive


def test_wheel_installs_one_top_level_name(wheel):
    top = {name.split("/")[0] for name in wheel.namelist()}
    assert top == {"gyroemu", f"gyroemu-{version('gyroemu')}.dist-info"}
    assert "gyroemu/py.typed" in wheel.namelist()


def test_wheel_carries_every_source_file_and_config(wheel):
    """Each file of the source folders (``.py`` and the TOML configs) is in the wheel, under ``gyroemu/``."""
    expected = {
        f"gyroemu/{path.relative_to(ROOT).as_posix()}"
        for folder in SOURCE_FOLDERS
        for path in (ROOT / folder).rglob("*")
        if path.is_file() and path.suffix in (".py", ".toml")
    }
    assert sum(name.startswith("gyroemu/configs/") and name.endswith(".toml") for name in expected) >= 20
    assert expected - set(wheel.namelist()) == set()


def test_console_script_is_the_cli():
    (script,) = [e for e in entry_points(group="console_scripts") if e.name == "gyroemu"]
    assert script.value == "gyroemu.pipelines.cli:main"


def test_the_installed_package_is_what_is_tested():
    """CI sets GYROEMU_TEST_INSTALLED: then gyroemu must come from the venv, not from this checkout."""
    if not os.environ.get("GYROEMU_TEST_INSTALLED"):
        pytest.skip("GYROEMU_TEST_INSTALLED is not set: an editable install may import the checkout")
    import gyroemu.dynamics

    for module in (gyroemu, gyroemu.dynamics):
        assert not Path(module.__file__).resolve().is_relative_to(ROOT), module.__file__


def test_version_comes_from_the_package_metadata():
    assert gyroemu.__version__ == version("gyroemu")
    done = subprocess.run([sys.executable, "-m", "gyroemu", "--version"], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == f"gyroemu {version('gyroemu')}"


def test_importing_gyroemu_changes_nothing_in_numba():
    """numba's class, its config and a user's own compiled function are untouched by gyroemu, even after
    gyroemu has compiled (or loaded from its cache) a function of its own."""
    code = """
import json, numba
from numba.core.dispatcher import Dispatcher
before = (Dispatcher.compile, {k: repr(v) for k, v in vars(numba.config).items() if k.isupper()})
import gyroemu.dynamics, gyroemu.sensors, gyroemu.pipelines.estimation
from gyroemu.dynamics.rotation import quat_multiply
from gyroemu.dynamics import load_scenario
quat_multiply([1.0, 0, 0, 0], [0, 1.0, 0, 0])
load_scenario("heavy_top").simulate(duration=0.01)
@numba.njit
def mine(x):
    return x + 1
mine(1)
after = (Dispatcher.compile, {k: repr(v) for k, v in vars(numba.config).items() if k.isupper()})
print(json.dumps([before[0] is after[0], before[1] == after[1], "compile" in vars(mine)]))
"""
    assert json.loads(run_python(code)) == [True, True, False]


HEAVY = ("numba", "matplotlib", "zenoh", "filterpy")


@pytest.mark.parametrize(
    "what, code",
    [
        ("import gyroemu", "import gyroemu"),
        ("gyroemu --help", "from gyroemu.pipelines.cli import build_parser; build_parser().format_help()"),
        ("gyroemu scenarios", "from gyroemu.pipelines.cli import main; main(['scenarios'])"),
        ("gyroemu presets", "from gyroemu.pipelines.cli import main; main(['presets'])"),
    ],
)
def test_light_commands_import_no_heavy_library(what, code):
    """The listing commands load neither numba, matplotlib, zenoh nor filterpy (issue: CLI start-up)."""
    out = run_python(f"import sys\n{code}\nprint('\\n' + repr(sorted(set({HEAVY!r}) & set(sys.modules))))")
    assert out.splitlines()[-1] == "[]", what


def _functions_of(name: str, obj: object) -> list[tuple[str, object]]:
    """The callables a public name stands for: itself, or a class's public methods and properties."""
    import inspect

    if inspect.isfunction(obj):
        return [(name, obj)]
    if not inspect.isclass(obj):
        return []
    found = []
    for key, member in vars(obj).items():
        if isinstance(member, (staticmethod, classmethod)):
            member = member.__func__
        elif isinstance(member, property):
            member = member.fget
        if not inspect.isfunction(member) or (key.startswith("_") and key != "__init__"):
            continue
        if key == "__init__" and member.__qualname__.startswith("_no_init"):  # typing.Protocol's own
            continue
        found.append((f"{name}.{key}", member))
    return found


@pytest.mark.parametrize("package", ["gyroemu.dynamics", "gyroemu.sensors", "gyroemu.pipelines.estimation"])
def test_public_api_is_fully_annotated(package):
    """Every name a package exports: each parameter and each return annotated (mypy checks the rest)."""
    import importlib
    import inspect

    module = importlib.import_module(package)
    missing = []
    for name in module.__all__:
        for qualified, function in _functions_of(name, getattr(module, name)):
            signature = inspect.signature(function)
            for p in signature.parameters.values():
                if p.name not in ("self", "cls") and p.annotation is inspect.Parameter.empty:
                    missing.append(f"{qualified}({p.name})")
            if signature.return_annotation is inspect.Signature.empty and function.__name__ != "__init__":
                missing.append(f"{qualified} -> ?")
    assert missing == []


def test_numba_caches_gyroemu_per_user_and_version(tmp_path):
    """gyroemu's compiled functions are cached under ``$XDG_CACHE_HOME/gyroemu/<version>/numba``, beside
    the compile lock, and a second process loads them from there (its index lists the signature); the
    quaternion kernels too, and nothing is written beside the installed sources."""
    code = """
import numpy as np
from gyroemu.sensors.noise import sensor_noise
from gyroemu.dynamics.rotation import quat_multiply, quat_rotate
sensor_noise(np.random.default_rng(0), (10, 3), 0.01, white=1.0)
quat_rotate(quat_multiply(np.ones((2, 4)), np.ones(4)), np.ones(3))
from gyroemu.dynamics.jit import cache_path, lock_path
print(cache_path()); print(lock_path())
"""
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path)}
    sources = [Path(importlib.import_module(f"gyroemu.{name}").__file__).parent for name in ("dynamics", "sensors")]
    beside_sources = lambda: {p: p.stat().st_mtime_ns for folder in sources for p in folder.rglob("*.nb[ic]")}
    before = beside_sources()
    done = subprocess.run([sys.executable, "-P", "-c", code], capture_output=True, text=True, cwd=ROOT.parent, env=env)
    assert done.returncode == 0, done.stderr
    cache, lock = (Path(line) for line in done.stdout.split())
    assert cache == tmp_path / "gyroemu" / version("gyroemu") / "numba" and lock.parent == cache.parent
    assert len(list(cache.rglob("noise._ar1_sum_into-*.nbi"))) == 1
    assert len(list(cache.rglob("rotation._multiply_rows-*.nbi"))) == 1
    assert len(list(cache.rglob("rotation._rotate_rows-*.nbi"))) == 1
    assert beside_sources() == before
    written = {p: p.stat().st_mtime_ns for p in cache.rglob("*.nb*")}
    assert any(p.suffix == ".nbc" for p in written)
    again = subprocess.run([sys.executable, "-P", "-c", code], capture_output=True, text=True, cwd=ROOT.parent, env=env)
    assert again.returncode == 0, again.stderr
    # Loaded, not compiled again: the second process wrote nothing into the cache.
    assert {p: p.stat().st_mtime_ns for p in cache.rglob("*.nb*")} == written


def test_a_changed_compiled_callee_in_another_file_is_compiled_again(tmp_path):
    """numba checks a cached function against its own file only; gyroemu's cache stamps the files of
    its compiled callees too, so a caller whose callee (in another module) changed is not loaded stale,
    and an unchanged one is still loaded from the cache."""
    package = tmp_path / "pkg"
    package.mkdir()
    (package / "__init__.py").write_text("")
    callee = package / "callee.py"
    callee.write_text("from gyroemu.dynamics.jit import njit\n\n\n@njit\ndef step(x):\n    return x + 1.0\n")
    (package / "caller.py").write_text(
        "from gyroemu.dynamics.jit import njit\n\nfrom . import callee\n\n\n"
        "@njit\ndef twice(x):\n    return callee.step(callee.step(x))\n"
    )
    code = "from pkg.caller import twice; print(twice(0.0))"
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "cache"), "PYTHONPATH": str(tmp_path)}

    def run() -> str:
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, env=env)
        assert done.returncode == 0, done.stderr
        return done.stdout.strip()

    assert run() == "2.0"
    cache = tmp_path / "cache"
    written = {p: p.stat().st_mtime_ns for p in cache.rglob("*.nb*")}
    assert run() == "2.0"
    assert {p: p.stat().st_mtime_ns for p in cache.rglob("*.nb*")} == written  # loaded, not compiled
    callee.write_text(callee.read_text().replace("x + 1.0", "x + 5.0"))
    assert run() == "10.0"


def _hits_and_misses(folder: Path, **env: str) -> str:
    """Call ``f`` of ``folder``/kernels.py once in a new process with the user cache in ``folder``/cache
    and ``env`` added: "hits misses" of numba's cache."""
    code = "from kernels import f; f(1.0); print(sum(f.stats.cache_hits.values()), sum(f.stats.cache_misses.values()))"
    environment = {**os.environ, "XDG_CACHE_HOME": str(folder / "cache"), "PYTHONPATH": str(folder), **env}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=folder, env=environment)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def test_a_set_option_is_loaded_from_the_cache_in_every_process(tmp_path):
    """A set option (``fastmath``, as the ring laser's kernels take it) was part of the cache entry in its
    set's order, which follows the strings' hashes and so differs from process to process: the entry
    was compiled again and rewritten in most processes. Each hash seed below is another process order."""
    (tmp_path / "kernels.py").write_text(
        'from gyroemu.dynamics.jit import njit\n\n\n@njit(fastmath={"arcp", "nsz", "contract", "reassoc"})\n'
        "def f(x):\n    return x * 2.0\n"
    )
    assert _hits_and_misses(tmp_path, PYTHONHASHSEED="0") == "0 1"  # compiled and cached
    # 24 orders of four strings: with the order in the entry, 4 other seeds all hit by chance 1 in 24⁴
    assert [_hits_and_misses(tmp_path, PYTHONHASHSEED=str(seed)) for seed in range(1, 5)] == ["1 0"] * 4


def test_compiled_options_are_part_of_the_cache_entry(tmp_path):
    """numba's cache index leaves out flags such as ``nogil``; gyroemu's entries carry the options, so a
    function whose options changed (its file unchanged) is compiled again instead of loaded with the old
    ones (a loop compiled to hold the GIL would keep holding it)."""
    (tmp_path / "kernels.py").write_text(
        "import os\n\nfrom gyroemu.dynamics.jit import njit\n\n\n"
        '@njit(nogil=os.environ["KERNEL_NOGIL"] == "1")\ndef f(x):\n    return x * 2.0\n'
    )
    assert _hits_and_misses(tmp_path, KERNEL_NOGIL="1") == "0 1"  # compiled and cached
    assert _hits_and_misses(tmp_path, KERNEL_NOGIL="1") == "1 0"  # loaded
    assert _hits_and_misses(tmp_path, KERNEL_NOGIL="0") == "0 1"  # the same file, other options: compiled again
    assert _hits_and_misses(tmp_path, KERNEL_NOGIL="0") == "1 0"

"""Files written whole or not at all (:mod:`gyroemu.pipelines.formats.atomic`), with the mode a plain
``open`` gives, and the up-front check of an output's folder."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from gyroemu.pipelines.formats.atomic import folder_problem, write_atomic, write_text_atomic


@pytest.mark.parametrize("umask", [0o022, 0o077, 0o002])
def test_the_output_gets_the_mode_open_gives(tmp_path: Path, umask: int):
    old = os.umask(umask)
    try:
        plain = tmp_path / "plain.txt"
        plain.write_text("x")
        written = write_text_atomic(tmp_path / "atomic.txt", "x")
    finally:
        os.umask(old)
    assert stat.S_IMODE(written.stat().st_mode) == stat.S_IMODE(plain.stat().st_mode) == 0o666 & ~umask


def test_a_failed_write_leaves_the_target_and_no_temporary_file(tmp_path: Path):
    target = tmp_path / "keep.txt"
    target.write_text("user's")

    def fail(f) -> None:
        f.write(b"half")
        raise RuntimeError("disk gone")

    with pytest.raises(RuntimeError):
        write_atomic(target, fail)
    assert target.read_text() == "user's"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.txt"]


def test_folder_problem_names_what_is_wrong(tmp_path: Path):
    assert folder_problem(tmp_path) is None
    assert folder_problem(tmp_path / "missing") == "no such folder"
    (tmp_path / "file").write_text("x")
    assert folder_problem(tmp_path / "file") == "not a folder"
    if os.geteuid() != 0:  # root may write anywhere a mount allows
        locked = tmp_path / "locked"
        locked.mkdir(mode=0o555)
        assert folder_problem(locked) == "not writable"


def test_output_folder_problem_names_the_folder_a_missing_one_would_be_made_in(tmp_path: Path, monkeypatch):
    from gyroemu.pipelines.formats import atomic

    assert atomic.output_folder_problem(tmp_path / "a" / "b") is None  # made in tmp_path, which can take it
    (tmp_path / "file").write_text("x")
    assert atomic.output_folder_problem(tmp_path / "file") == f"{tmp_path / 'file'} is not a folder"
    assert atomic.output_folder_problem(tmp_path / "file" / "sub") == f"{tmp_path / 'file'}: not a folder"
    monkeypatch.setattr(atomic, "folder_problem", lambda f: "read-only file system" if Path(f) == tmp_path else None)
    assert atomic.output_folder_problem(tmp_path / "a" / "b") == f"{tmp_path}: read-only file system"


def test_an_existing_file_keeps_its_own_mode(tmp_path: Path):
    """Written over (a --force), a file keeps the mode its owner gave it, as ``open`` would leave it."""
    target = tmp_path / "k.yaml"
    target.write_text("old")
    target.chmod(0o600)
    write_text_atomic(target, "new")
    assert target.read_text() == "new" and stat.S_IMODE(target.stat().st_mode) == 0o600
    target.chmod(0o640)
    write_text_atomic(target, "newer")
    assert stat.S_IMODE(target.stat().st_mode) == 0o640

"""Files written whole or not at all (:mod:`gyroemu.pipelines.formats.atomic`), with the mode a plain
``open`` gives, and the up-front checks of an output's folder and file."""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

import pytest
from full_disk import contents, disk_full_at

from gyroemu.pipelines.formats.atomic import folder_problem, staged_files, write_atomic, write_text_atomic


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


def test_output_file_problem_says_the_first_of_folder_input_its_folder_existing(tmp_path: Path, monkeypatch):
    """One check of an output file for every job, in one order and one wording: a folder, an input (even
    with --force; by any path to it), a folder that cannot take it, an existing file (or link) without
    --force."""
    from gyroemu.pipelines.formats import atomic

    log, plot = tmp_path / "log.mcap", tmp_path / "p.png"
    log.write_text("x")
    (tmp_path / "dir.png").mkdir()
    (tmp_path / "sub").mkdir()
    os.symlink(tmp_path / "gone", tmp_path / "dangling.png")
    problem = atomic.output_file_problem
    assert problem(plot, force=False, inputs=(log,)) is None
    assert problem(tmp_path / "dir.png", force=True) == f"{tmp_path / 'dir.png'} is a folder: name a file in it"
    never = "inputs are never overwritten, even with --force"
    assert problem(log, force=True, inputs=(plot, log)) == f"{log} is an input: {never}"
    again = tmp_path / "sub" / ".." / "log.mcap"
    assert problem(again, force=True, inputs=[log]) == f"{again} is an input ({log}): {never}"
    assert problem(tmp_path / "no" / "p.png", force=True) == f"{tmp_path / 'no'}: no such folder"
    assert problem(log, force=False) == f"{log} exists (use --force to overwrite it)"
    assert problem(log, force=True) is None
    dangling = tmp_path / "dangling.png"
    assert problem(dangling, force=False) == f"{dangling} exists (use --force to overwrite it)"
    monkeypatch.setattr(atomic, "folder_problem", lambda f: "read-only file system" if Path(f) == tmp_path else None)
    assert problem(log, force=False) == f"{tmp_path}: read-only file system"  # before "exists"
    assert problem(log, force=False, inputs=[log]) == f"{log} is an input: {never}"  # before the folder


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


@pytest.mark.parametrize("n", [1, 2, 3])
def test_staged_files_put_every_file_in_place_or_none(tmp_path: Path, monkeypatch, n: int):
    """A full disk at any file of a staged output leaves the folder as it was (the earlier files, the
    one to remove, no temporary file); a folder it made is removed again."""
    out = tmp_path / "report"
    out.mkdir()
    (out / "a.txt").write_text("earlier a")
    (out / "b.png").write_bytes(b"earlier b")
    (out / "old.png").write_bytes(b"earlier plot")
    before = contents(out)
    asked = disk_full_at(monkeypatch, n)
    with pytest.raises(OSError) as caught:
        with staged_files(out) as stage:
            stage.write_text(out / "a.txt", "new a")
            stage.write(out / "b.png", lambda f: f.write(b"new b"))
            stage.remove(out / "old.png")
            stage.write_text(out / "c.txt", "new c")
    assert caught.value.errno == errno.ENOSPC and len(asked) == n
    assert contents(out) == before
    made = tmp_path / "made" / "report"
    with pytest.raises(KeyboardInterrupt):
        with staged_files(made) as stage:
            stage.write_text(made / "a.txt", "a")
            raise KeyboardInterrupt
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report"]


def test_staged_files_complete_replace_remove_and_keep_the_mode(tmp_path: Path):
    out = tmp_path / "new" / "report"
    with staged_files(out) as stage:
        assert stage.write_text(out / "a.txt", "a") == out / "a.txt"
        assert not (out / "a.txt").exists()  # nothing in place before the end
    assert contents(out) == {"a.txt": b"a"}
    (out / "a.txt").chmod(0o640)
    (out / "old.png").write_bytes(b"x")
    with staged_files(out) as stage:
        stage.write_text(out / "a.txt", "A")
        stage.write(out / "b.bin", lambda f: f.write(b"B"))
        stage.remove(out / "old.png")
    assert contents(out) == {"a.txt": b"A", "b.bin": b"B"}
    assert stat.S_IMODE((out / "a.txt").stat().st_mode) == 0o640

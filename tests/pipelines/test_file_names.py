"""File names (:mod:`gyroemu.pipelines.formats.file_names`): one file by any path to it."""

from __future__ import annotations

import os
from pathlib import Path

from gyroemu.pipelines.formats.file_names import repeated_file, same_file


def test_same_file_by_any_path_to_it(tmp_path: Path):
    log = tmp_path / "a.mcap"
    log.write_bytes(b"x")
    (tmp_path / "sub").mkdir()
    os.symlink(log, tmp_path / "soft.mcap")
    os.link(log, tmp_path / "hard.mcap")
    assert same_file(log, tmp_path / "sub" / ".." / "a.mcap")
    assert same_file(log, tmp_path / "soft.mcap") and same_file(tmp_path / "hard.mcap", log)
    assert same_file(tmp_path / "new.mcap", tmp_path / "sub" / ".." / "new.mcap")  # neither exists yet
    assert not same_file(log, tmp_path / "other.mcap")
    os.symlink(tmp_path / "loop", tmp_path / "loop")
    assert not same_file(tmp_path / "loop", log)


def test_repeated_file_names_the_first_and_the_second(tmp_path: Path):
    a, b = tmp_path / "a", tmp_path / "b"
    a.write_text("a")
    b.write_text("b")
    os.link(a, tmp_path / "a2")
    assert repeated_file([a, b]) is None
    assert repeated_file([a, b, tmp_path / "a2"]) == (a, tmp_path / "a2")

"""Running the ``gyroemu`` command line in the test's own process, output captured."""

from __future__ import annotations

import contextlib
import io

from gyroemu.pipelines import cli


def run_cli(argv: list[str]) -> tuple[int, str, str]:
    """``gyroemu ARGV`` in this process: (exit status, stdout, stderr). Bad usage ends in argparse's
    ``SystemExit(2)``, which counts as the status it carries."""
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        try:
            code = cli.main(argv)
        except SystemExit as e:
            code = e.code if isinstance(e.code, int) else 1
    return code, stdout.getvalue(), stderr.getvalue()

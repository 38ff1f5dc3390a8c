"""The command line's logging: one line per message on stderr, ``gyroemu: <level>: <message>``.

:func:`cli_logging` is what :func:`gyroemu.pipelines.cli.main` runs a command in: Python warnings
(``warnings.warn``, e.g. :class:`~gyroemu.pipelines.formats.mcap_log.LogWarning`) are routed through
:func:`logging.captureWarnings` and printed as ``gyroemu: warning: <message>`` on one line (no
file:line, no source line), and the ``gyroemu`` loggers print the same way. ``-q`` shows errors
only, ``-v`` shows info and debug messages too. Everything is undone when the block ends, so the
library never configures logging by itself (importing it changes nothing) and :func:`main` can run
more than once in a process.
"""

from __future__ import annotations

import contextlib
import logging
import sys
import warnings
from collections.abc import Iterator
from typing import TextIO

__all__ = ["OneLineFormatter", "cli_logging", "verbosity_level"]

_LOGGERS = ("gyroemu", "py.warnings")
"""The loggers the command line prints: the library's and the one :func:`logging.captureWarnings` uses."""


class OneLineFormatter(logging.Formatter):
    """``gyroemu: <level>: <message>`` with the message's lines joined into one."""

    def format(self, record: logging.LogRecord) -> str:
        """The record as one line (its traceback, if any, is not shown).

        Parameters
        ----------
        record : logging.LogRecord

        Returns
        -------
        str
        """
        text = " ".join(line.strip() for line in record.getMessage().splitlines() if line.strip())
        return f"gyroemu: {record.levelname.lower()}: {text}"


class _StderrHandler(logging.StreamHandler[TextIO]):
    """A handler writing to whatever ``sys.stderr`` is when a record is emitted (tests replace it)."""

    @property
    def stream(self) -> TextIO:  # noqa: D102 - StreamHandler's attribute
        return sys.stderr

    @stream.setter
    def stream(self, value: TextIO) -> None:
        pass


def _warning_text(
    message: Warning | str, category: type[Warning], filename: str, lineno: int, line: str | None = None
) -> str:
    """:func:`warnings.formatwarning` while :func:`cli_logging` runs: the message alone."""
    return str(message)


def verbosity_level(quiet: bool = False, verbose: bool = False) -> int:
    """The logging level of ``-q`` / ``-v``.

    Parameters
    ----------
    quiet : bool
        ``-q``: errors only.
    verbose : bool
        ``-v``: info and debug messages too.

    Returns
    -------
    int
        ``logging.ERROR``, ``logging.DEBUG`` or (neither) ``logging.WARNING``.
    """
    if quiet:
        return logging.ERROR
    return logging.DEBUG if verbose else logging.WARNING


@contextlib.contextmanager
def cli_logging(level: int = logging.WARNING) -> Iterator[None]:
    """Print warnings and the ``gyroemu`` loggers' records at ``level`` and above, one line each, on
    stderr, for the duration of the block; the previous logging and warnings set-up is back after.

    Parameters
    ----------
    level : int
        The lowest level shown (:func:`verbosity_level`).

    Yields
    ------
    None
    """
    handler = _StderrHandler()
    handler.setFormatter(OneLineFormatter())
    saved = []
    for name in _LOGGERS:
        logger = logging.getLogger(name)
        saved.append((logger, logger.level, logger.propagate))
        logger.addHandler(handler)
        logger.setLevel(level)
        logger.propagate = False
    format_warning = warnings.formatwarning
    warnings.formatwarning = _warning_text
    logging.captureWarnings(True)
    try:
        yield
    finally:
        logging.captureWarnings(False)
        warnings.formatwarning = format_warning
        for logger, old_level, propagate in saved:
            logger.removeHandler(handler)
            logger.setLevel(old_level)
            logger.propagate = propagate

"""gyroemu's errors: one hierarchy, below every layer, that the command line maps to exit status 2.

- :class:`GyroemuError`: the base of every error gyroemu raises about its input;
- :class:`ConfigError`: a config file, key or value (``.file``, ``.key``);
- :class:`LogError`: a log file that cannot be read (``.file``, and where known ``.offset``, the byte
  offset of the record at fault; a log error is not a config error).

Both are also ``ValueError``\\ s, as they were before this module existed, so code that caught a bad
value still catches them.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["ConfigError", "GyroemuError", "LogError"]


class GyroemuError(Exception):
    """Bad input that gyroemu names: ``reason`` says what is wrong, ``file`` where (or None)."""

    def __init__(self, reason: str, *, file: str | Path | None = None) -> None:
        self.reason = reason
        self.file = None if file is None else str(file)
        super().__init__(str(self))

    def _where(self) -> list[str]:
        return [self.file] if self.file else []

    def __str__(self) -> str:
        where = self._where()
        return (": ".join(where) + ": " if where else "") + self.reason


class ConfigError(GyroemuError, ValueError):
    """A config file, key or value that gyroemu cannot use.

    Attributes
    ----------
    file : str or None
        The file at fault, when there is one.
    key : str or None
        Dotted key within the file (``body.inertia_kgm2``), when one key is at fault.
    reason : str
        What is wrong, in words.
    """

    def __init__(self, reason: str, *, file: str | Path | None = None, key: str | None = None) -> None:
        self.key = key
        super().__init__(reason, file=file)

    def _where(self) -> list[str]:
        return super()._where() + ([f"key '{self.key}'"] if self.key else [])


class LogError(GyroemuError, ValueError):
    """A log file gyroemu cannot read: not MCAP, corrupt, or without the messages it needs.

    Attributes
    ----------
    file : str or None
        The log.
    offset : int or None
        Byte offset of the record at fault, when one record is.
    reason : str
        What is wrong, in words.
    """

    def __init__(self, reason: str, *, file: str | Path | None = None, offset: int | None = None) -> None:
        self.offset = offset  # the reason says it in words too ("corrupt chunk at byte 1234")
        super().__init__(reason, file=file)

"""A command's text output that raises a signal in the process when a line is printed: how a test stops
a live job at a chosen moment (its own handlers take the signal in its live stretch)."""

from __future__ import annotations

import signal


class SignalOn:
    """An ``out`` for a job that raises ``sig`` when ``marker`` is written; ``text`` keeps what was."""

    def __init__(self, sig: signal.Signals, marker: str) -> None:
        self.sig, self.marker, self.text = sig, marker, []

    def write(self, text: str) -> int:
        self.text.append(text)
        if self.marker in text:
            signal.raise_signal(self.sig)
        return len(text)

    def flush(self) -> None:
        pass

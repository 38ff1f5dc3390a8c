"""What gyroemu's recorder reads of a zenoh sample, for tests that feed it without a session."""

from __future__ import annotations


class Payload:
    """A zenoh payload (``ZBytes``): its bytes."""

    def __init__(self, data: bytes) -> None:
        self.data = data

    def to_bytes(self) -> bytes:
        return self.data


class Sample:
    """A zenoh sample as :meth:`gyroemu.pipelines.transport.record.Recorder.add` reads it: key expression,
    payload and attachment (None: the sample has none)."""

    def __init__(self, key: str, payload: bytes, attachment: bytes | None = None) -> None:
        self.key_expr = key
        self.payload = Payload(payload)
        self.attachment = None if attachment is None else Payload(attachment)

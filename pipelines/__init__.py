"""gyroemu's jobs and transports: simulate, record, replay, stream, estimate, and the command line."""

__all__: list[str] = []

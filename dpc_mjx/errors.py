"""The one exception type of the library."""


class DpcError(Exception):
    """An error raised by dpc_mjx itself. Its message says what was wrong and what to change."""

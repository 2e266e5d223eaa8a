"""The one exception family for user-facing errors.

A `DarthandError` message is a single line that names the file, field or prim at fault. The CLI prints it and exits
with code 2; anything else escaping to the CLI is a bug.
"""


class DarthandError(Exception):
    """A user-facing error: bad input, a missing file, an unreadable asset."""


class InputError(DarthandError):
    """A file or argument the user gave is missing, malformed or inconsistent."""


class UnsafePickleError(InputError):
    """A pickle asked for a global outside the allowed set; nothing in it was executed."""


def where(path, field=None) -> str:
    """Format 'path' or 'path: field' for error messages."""
    return f"{path}: {field}" if field else f"{path}"

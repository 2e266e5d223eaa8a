"""The studio's refusal of a request: an InputError carrying its HTTP status (a module of its own, so that every
studio module can raise it without importing the build)."""

from __future__ import annotations

from darthand.errors import InputError


class RequestError(InputError):
    """A request the studio refuses: `status` the HTTP status (4xx), the message one line naming what is wrong."""

    def __init__(self, status: int, message: str):
        super().__init__(message)
        self.status = status

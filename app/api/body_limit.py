"""A size limit on request bodies other than uploads, enforced before and while they are read.

Uploads (multipart/form-data) have their own limits, checked part by part while streaming to disk
(`app.api.uploads`). Every other body is JSON that the framework reads into memory whole, so without
this a 50 MB body costs the API several times that in parsed objects.
"""

from __future__ import annotations

import re

from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from app.api.errors import error_response


class BodyTooLarge(HTTPException):
    code = "body_too_large"

    def __init__(self, limit: int) -> None:
        super().__init__(
            413,
            f"the request body exceeds the limit of {limit} bytes; send fewer points per request",
        )


# the one operation that takes multipart (and streams it to disk under its own limits)
_UPLOAD_PATH = re.compile(r"^/courts/[^/]+/calibrations$")


def _is_upload(scope: Scope) -> bool:
    if scope.get("method") != "POST" or not _UPLOAD_PATH.match(scope.get("path", "")):
        return False
    for name, value in scope.get("headers", ()):
        if name == b"content-type":
            return value.split(b";", 1)[0].strip().lower() == b"multipart/form-data"
    return False


def _declared_length(scope: Scope) -> int | None:
    for name, value in scope.get("headers", ()):
        if name == b"content-length":
            return int(value) if value.isdigit() else None
    return None


class BodyLimitMiddleware:
    """413 for a non-upload body over `max_bytes`: at once from Content-Length, else while reading."""

    def __init__(self, app: ASGIApp, max_bytes: int) -> None:
        self.app = app
        self.max_bytes = max_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or _is_upload(scope):
            await self.app(scope, receive, send)
            return
        declared = _declared_length(scope)
        if declared is not None and declared > self.max_bytes:
            too_large = BodyTooLarge(self.max_bytes)
            response = error_response(413, too_large.code, too_large.detail)
            await response(scope, receive, send)
            return
        received = 0

        async def counting_receive() -> Message:
            nonlocal received
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > self.max_bytes:
                    # raised inside the framework's body read: it reaches the HTTPException handler
                    raise BodyTooLarge(self.max_bytes)
            return message

        await self.app(scope, counting_receive, send)

"""A response sent before its request's body was read to the end closes the connection.

The API answers some requests without reading their whole body: an upload over the size limit
(413 while it streams), of a type it refuses (415 from the first bytes), to an unknown court (404
before a byte is read), a JSON body over its limit. uvicorn then keeps the connection open and
reads the rest of the body only to discard it, for as long as the client sends: a refused 50 GB
upload would still be received in full, and a client that sends its whole body before it reads
the answer learns of the refusal only at the end. `Connection: close` on such a response makes
uvicorn close the connection once the answer is written, and tells the client not to send more.
"""

from __future__ import annotations

from starlette.datastructures import Headers, MutableHeaders
from starlette.types import ASGIApp, Message, Receive, Scope, Send


def _has_body(scope: Scope) -> bool:
    headers = Headers(scope=scope)
    return "transfer-encoding" in headers or headers.get("content-length", "0") not in ("", "0")


class CloseOnUnreadBodyMiddleware:
    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or not _has_body(scope):
            await self.app(scope, receive, send)
            return
        body_read = False

        async def watching_receive() -> Message:
            nonlocal body_read
            message = await receive()
            # the body's last chunk, or the client went away: nothing more will come
            if message["type"] != "http.request" or not message.get("more_body", False):
                body_read = True
            return message

        async def closing_send(message: Message) -> None:
            if message["type"] == "http.response.start" and not body_read:
                MutableHeaders(scope=message)["Connection"] = "close"
            await send(message)

        await self.app(scope, watching_receive, closing_send)

"""Headers every response carries, and the CSP of the browser page.

- `X-Content-Type-Options: nosniff`: a browser never runs a response as a type it was not sent as
  (an uploaded "image" as script, a JSON error as HTML).
- `frame-ancestors 'none'` (and the older `X-Frame-Options: DENY`): no other site can frame the
  page to trick a click.
- A CSP on everything: the page gets `PAGE_CSP` (its script, style and pictures come from this
  server only; it has no inline script or style), /docs sets its own, and any other response (JSON,
  images) gets `default-src 'none'`, so even a response opened as a document can do nothing.
"""

from __future__ import annotations

from starlette.datastructures import MutableHeaders
from starlette.types import ASGIApp, Message, Receive, Scope, Send

PAGE_CSP = (
    "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self'; "
    "connect-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'"
)
API_CSP = "default-src 'none'; frame-ancestors 'none'"
ALWAYS = {
    "X-Content-Type-Options": "nosniff",
    "X-Frame-Options": "DENY",
    "Referrer-Policy": "no-referrer",
}


class SecurityHeadersMiddleware:
    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = MutableHeaders(scope=message)
                for name, value in ALWAYS.items():
                    headers[name] = value
                if "content-security-policy" not in headers:
                    headers["Content-Security-Policy"] = API_CSP
            await send(message)

        await self.app(scope, receive, send_with_headers)

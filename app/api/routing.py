"""The route class of every API router: request checks that need no dependency.

FastAPI resolves each dependency of an operation on every request, at a few tens of microseconds
each; a router-wide dependency that is a no-op for almost every request (no query string) still
paid that on /project. The unknown-query check runs here instead, before FastAPI resolves anything,
and only when the request has a query string.
"""

from __future__ import annotations

from collections.abc import Callable, Coroutine
from typing import Any

from fastapi import Request, Response
from fastapi.routing import APIRoute

from app.api.errors import ApiError


class ApiRoute(APIRoute):
    """APIRoute that refuses query parameters the operation does not have (422)."""

    def get_route_handler(self) -> Callable[[Request], Coroutine[Any, Any, Response]]:
        handler = super().get_route_handler()

        async def checked(request: Request) -> Response:
            if request.scope.get("query_string"):
                reject_unknown_query(request)
            return await handler(request)

        return checked


def reject_unknown_query(request: Request) -> None:
    """422 for a query parameter the operation does not have: a misspelt `limt=5` is silently
    ignored otherwise, and the caller never learns why the limit did not apply."""
    route = request.scope.get("route")
    dependant = getattr(route, "dependant", None)
    # the browser page and its files are not API operations: links may carry any query
    if dependant is None or not request.query_params or not route.include_in_schema:  # type: ignore[union-attr]
        return
    known = {p.alias for p in _query_params(dependant)}
    unknown = sorted(set(request.query_params) - known)
    if unknown:
        expected = ", ".join(sorted(known)) or "none"
        raise ApiError(
            422,
            "unknown_query_parameter",
            f"unknown query parameter(s) {', '.join(unknown)}; this operation takes: {expected}",
        )


def _query_params(dependant: Any) -> list[Any]:
    params = list(dependant.query_params)
    for sub in dependant.dependencies:
        params += _query_params(sub)
    return params

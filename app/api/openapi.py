"""The OpenAPI document says what the server does: every error status an operation can answer,
with the one error body all errors share.

FastAPI documents only 200 and its own 422 shape; the statuses below come from the dependencies
and middleware every operation goes through, so they are added here by rule rather than repeated
on each route:
- 401 where a key is required, 503 where the database is needed (it may be down);
- 404 where the path or body names a resource (another tenant's looks the same as a missing one);
- 422 everywhere: parameters and bodies are validated, and unknown query parameters refused;
- 400 (unparseable JSON) and 413 (over the body limit) where there is a JSON body;
- 413, 415 and 429 for the upload (size limits, not multipart, tenant limits).
"""

from __future__ import annotations

from typing import Any

from fastapi import FastAPI
from fastapi.openapi.utils import get_openapi

ERROR_REF = {"$ref": "#/components/schemas/ErrorResponse"}
DESCRIPTIONS = {
    400: "The body is not parseable (e.g. JSON nested too deeply).",
    401: "Missing, unknown or revoked API key (`Authorization: Bearer <key>`).",
    404: "No such resource for this key's tenant (another tenant's looks the same).",
    413: "The body, a file or the images' pixels together are over a limit.",
    415: "Not multipart/form-data, or a file that is not a PNG/JPEG image or a supported video.",
    422: "A parameter, field or file is invalid; `error.code` and `error.message` say which.",
    429: "Too many requests or queued jobs for this tenant; retry after `Retry-After` seconds.",
    503: "The database is unavailable; retry after `Retry-After` seconds.",
}
HTTP_METHODS = ("get", "put", "post", "delete", "patch", "head", "options")


def error_statuses(path: str, method: str, operation: dict[str, Any]) -> set[int]:
    """The error statuses `operation` can answer, by the rules in the module docstring."""
    statuses: set[int] = set()
    content = operation.get("requestBody", {}).get("content", {})
    if operation.get("security"):
        statuses |= {401, 503}
    if "{" in path or path == "/project":
        statuses.add(404)
    statuses.add(422)  # at least an unknown query parameter (routing.ApiRoute)
    if "application/json" in content:
        statuses |= {400, 413}
    if "multipart/form-data" in content:
        statuses |= {413, 415, 429}
    if path == "/readyz":
        statuses.add(503)
    return statuses


def _document_errors(document: dict[str, Any]) -> None:
    for path, item in document.get("paths", {}).items():
        for method, operation in item.items():
            if method not in HTTP_METHODS:
                continue
            responses = operation.setdefault("responses", {})
            for status in sorted(error_statuses(path, method, operation)):
                responses[str(status)] = {
                    "description": DESCRIPTIONS[status],
                    "content": {"application/json": {"schema": ERROR_REF}},
                }


def _drop_unused_validation_schemas(document: dict[str, Any]) -> None:
    # FastAPI's own 422 body; every 422 here has the ErrorResponse shape instead
    schemas = document.get("components", {}).get("schemas", {})
    for name in ("HTTPValidationError", "ValidationError"):
        schemas.pop(name, None)


def install_openapi(app: FastAPI, error_schema: dict[str, Any]) -> None:
    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            document = get_openapi(
                title=app.title,
                version=app.version,
                summary=app.summary,
                routes=app.routes,
            )
            components = document.setdefault("components", {}).setdefault("schemas", {})
            components.update(error_schema)
            _document_errors(document)
            _drop_unused_validation_schemas(document)
            app.openapi_schema = document
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]

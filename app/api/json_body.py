"""A JSON body parsed and validated in one pass (pydantic's JSON parser straight into the model).

FastAPI reads a body model by decoding the JSON with the standard library and then validating the
Python objects: for /project's 1000-point bodies that is most of the request's time. Operations
on the hot path take the body through `parsed_body` instead and declare it with `body_openapi`, so
the OpenAPI document still names the model (the schema is registered in `app.main`). Errors keep
the service's shape: any invalid body (malformed JSON, NaN, wrong types, too many points) raises
the same RequestValidationError FastAPI would, i.e. 422 `invalid_request`.
"""

from __future__ import annotations

from typing import Any, TypeVar

from fastapi import Request
from fastapi.exceptions import RequestValidationError
from pydantic import BaseModel, ValidationError

Model = TypeVar("Model", bound=BaseModel)


def body_openapi(model: type[BaseModel]) -> dict[str, Any]:
    """`openapi_extra` for an operation whose JSON body is `model`."""
    ref = {"$ref": f"#/components/schemas/{model.__name__}"}
    return {"requestBody": {"content": {"application/json": {"schema": ref}}, "required": True}}


def _is_json(content_type: str) -> bool:
    media = content_type.split(";", 1)[0].strip().lower()
    return media == "application/json" or (
        media.startswith("application/") and media.endswith("+json")
    )


async def parsed_body(request: Request, model: type[Model]) -> Model:
    """The request's JSON body as `model` (422 RequestValidationError when it is not one)."""
    content_type = request.headers.get("content-type")
    if content_type is not None and not _is_json(content_type):
        raise RequestValidationError(
            [
                {
                    "type": "model_attributes_type",
                    "loc": ("body",),
                    "msg": f"expected a JSON body (Content-Type: application/json), "
                    f"got {content_type[:80]!r}",
                    "input": None,
                }
            ]
        )
    raw = await request.body()
    try:
        return model.model_validate_json(raw)
    except ValidationError as exc:
        errors = exc.errors(include_url=False, include_input=False)
        raise RequestValidationError([{**e, "loc": ("body", *e["loc"])} for e in errors]) from None

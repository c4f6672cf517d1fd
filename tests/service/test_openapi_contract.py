"""The OpenAPI document says what the server does (the fast checks; schemathesis is the slow one)."""

from __future__ import annotations

import json

import httpx

from app.calib.court import COURT_SPECS
from tests.service.test_api import assert_error

METHODS = ("get", "post", "put", "delete", "patch")


def _operations(document: dict) -> list[tuple[str, str, dict]]:
    return [
        (path, method, op)
        for path, item in document["paths"].items()
        for method, op in item.items()
        if method in METHODS
    ]


def test_every_operation_documents_its_errors(client: httpx.Client) -> None:
    document = client.get("/openapi.json").json()
    error_ref = {"$ref": "#/components/schemas/ErrorResponse"}
    for path, method, op in _operations(document):
        responses = op["responses"]
        expected = {"422"}
        if op.get("security"):
            expected |= {"401", "503"}
        if "{" in path:
            expected.add("404")
        if "application/json" in op.get("requestBody", {}).get("content", {}):
            expected |= {"400", "413"}
        assert expected <= set(responses), (method, path, sorted(responses))
        for status in expected:
            schema = responses[status]["content"]["application/json"]["schema"]
            assert schema == error_ref, (method, path, status)
    upload = document["paths"]["/courts/{court_id}/calibrations"]["post"]["responses"]
    assert {"401", "404", "413", "415", "422", "429"} <= set(upload)
    assert "HTTPValidationError" not in document["components"]["schemas"]


def test_schema_details_match_the_server(client: httpx.Client) -> None:
    document = client.get("/openapi.json").json()
    text = json.dumps(document)
    assert "prefixItems" not in text  # unreadable for many validators
    assert "webp" not in text.lower()  # the server refuses WebP images
    form = document["paths"]["/courts/{court_id}/calibrations"]["post"]["requestBody"]
    files = form["content"]["multipart/form-data"]["schema"]["properties"]["files"]
    assert files["minItems"] == 1
    create = document["components"]["schemas"]["CourtCreate"]["properties"]["spec"]
    assert set(create["enum"]) == set(COURT_SPECS)
    listing = document["paths"]["/courts"]["get"]
    assert {p["name"] for p in listing["parameters"]} == {"limit", "offset"}
    history = document["paths"]["/courts/{court_id}/calibrations"]["get"]
    assert {p["name"] for p in history["parameters"]} == {"court_id", "limit", "offset"}
    for paged in ("CourtList", "CalibrationList"):
        assert "next_offset" in document["components"]["schemas"][paged]["properties"], paged


def test_405_names_every_method_of_the_path(client: httpx.Client, auth: dict[str, str]) -> None:
    response = client.delete("/courts", headers=auth)  # GET and POST are separate routes
    assert_error(response, 405, "method_not_allowed")
    assert set(response.headers["allow"].split(", ")) == {"GET", "POST"}
    response = client.put("/project", headers=auth)
    assert_error(response, 405)
    assert response.headers["allow"] == "POST"


def test_unknown_query_parameters_are_refused(client: httpx.Client, auth: dict[str, str]) -> None:
    response = client.get("/courts?limt=5", headers=auth)
    assert_error(response, 422, "unknown_query_parameter")
    assert "limt" in response.json()["error"]["message"]
    assert "limit" in response.json()["error"]["message"]
    assert client.get("/courts?limit=5", headers=auth).status_code == 200
    assert client.get("/?from=newsletter").status_code == 200  # the page takes any query

"""HTTP API in-process: auth, tenants, courts, error shape, /project validation, health."""

from __future__ import annotations

import httpx
import pytest

from app.db import repo
from app.db.migrate import head_revision
from app.db.session import make_engine, make_sessionmaker
from app.main import create_app
from app.settings import Settings
from tests.service.conftest import api_client, make_settings, new_key

pytestmark = pytest.mark.both_databases


def assert_error(response: httpx.Response, status: int, code: str | None = None) -> None:
    assert response.status_code == status, response.text
    body = response.json()
    assert set(body) == {"error"}
    assert set(body["error"]) == {"code", "message"}
    assert body["error"]["message"]
    if code is not None:
        assert body["error"]["code"] == code


def make_court(client: httpx.Client, auth: dict[str, str], name: str = "Court 1") -> str:
    response = client.post("/courts", json={"name": name, "spec": "wsf"}, headers=auth)
    assert response.status_code == 201, response.text
    return str(response.json()["id"])


def test_health_and_ready(client: httpx.Client, settings: Settings) -> None:
    assert client.get("/healthz").json() == {"status": "ok"}
    ready = client.get("/readyz")
    assert ready.status_code == 200
    assert ready.json()["status"] == "ready"
    assert ready.json()["revision"] == head_revision(settings)


def test_ready_fails_before_migrations(tmp_path, database_url: str | None) -> None:
    settings = make_settings(tmp_path / "fresh", database_url=database_url)
    with api_client(create_app(settings)) as client:
        assert client.get("/healthz").status_code == 200
        assert_error(client.get("/readyz"), 503, "migrations_pending")


def test_missing_and_invalid_keys_are_401(client: httpx.Client) -> None:
    for headers in ({}, {"Authorization": "Bearer nope"}, {"Authorization": "Basic abc"}):
        response = client.get("/courts", headers=headers)
        assert_error(response, 401, "unauthorized")
        assert response.headers["www-authenticate"] == "Bearer"


def test_revoked_key_is_401(client: httpx.Client, settings: Settings) -> None:
    engine = make_engine(settings)
    with make_sessionmaker(engine).begin() as session:
        row, key = repo.create_api_key(session, name="soon revoked")
    headers = {"Authorization": f"Bearer {key}"}
    assert client.get("/courts", headers=headers).status_code == 200
    with make_sessionmaker(engine).begin() as session:
        assert repo.revoke_api_key(session, row.id)
    engine.dispose()
    assert_error(client.get("/courts", headers=headers), 401)


def test_key_is_stored_only_as_a_hash(settings: Settings) -> None:
    key = new_key(settings)
    engine = make_engine(settings)
    with engine.connect() as conn:
        dump = "\n".join(str(row) for row in conn.exec_driver_sql("SELECT * FROM api_keys"))
    engine.dispose()
    assert key not in dump
    assert repo.hash_key(key) in dump


def test_court_crud(client: httpx.Client, auth: dict[str, str]) -> None:
    court_id = make_court(client, auth, "Centre court")
    got = client.get(f"/courts/{court_id}", headers=auth).json()
    assert got["name"] == "Centre court"
    assert got["spec"] == "wsf"
    assert got["active_calibration_id"] is None
    listed = client.get("/courts", headers=auth).json()["courts"]
    assert [c["id"] for c in listed] == [court_id]


@pytest.mark.parametrize(
    "body",
    [
        {"name": "x", "spec": "tennis"},
        {"name": ""},
        {"spec": "wsf"},
        {"name": "x", "colour": "red"},
        [1, 2],
    ],
)
def test_bad_court_bodies_are_422(client: httpx.Client, auth: dict[str, str], body) -> None:
    assert_error(client.post("/courts", json=body, headers=auth), 422)


def test_malformed_json_is_422(client: httpx.Client, auth: dict[str, str]) -> None:
    response = client.post(
        "/courts", content=b"{not json", headers={**auth, "content-type": "application/json"}
    )
    assert_error(response, 422)


def test_tenant_isolation(
    client: httpx.Client, auth: dict[str, str], other_auth: dict[str, str]
) -> None:
    court_id = make_court(client, auth)
    assert client.get("/courts", headers=other_auth).json()["courts"] == []
    for path in (
        f"/courts/{court_id}",
        f"/courts/{court_id}/camera",
        f"/courts/{court_id}/calibrations",
    ):
        assert_error(client.get(path, headers=other_auth), 404)
    assert_error(
        client.post(
            "/project", json={"court_id": court_id, "pixels": [[1, 2]]}, headers=other_auth
        ),
        404,
        "court_not_found",
    )
    assert_error(
        client.post(
            f"/courts/{court_id}/image-points", json={"points": [[1, 2]]}, headers=other_auth
        ),
        404,
        "court_not_found",
    )
    # the owner still sees it (and the cache entry made for the owner does not leak to the other)
    assert client.get(f"/courts/{court_id}", headers=auth).status_code == 200
    assert_error(
        client.post(
            "/project", json={"court_id": court_id, "pixels": [[1, 2]]}, headers=other_auth
        ),
        404,
    )


def test_camera_before_first_calibration(client: httpx.Client, auth: dict[str, str]) -> None:
    court_id = make_court(client, auth)
    assert_error(client.get(f"/courts/{court_id}/camera", headers=auth), 404, "no_calibration")
    assert_error(
        client.post("/project", json={"court_id": court_id, "pixels": [[1, 2]]}, headers=auth),
        404,
        "no_calibration",
    )


def test_unknown_ids_are_404(client: httpx.Client, auth: dict[str, str]) -> None:
    assert_error(client.get("/jobs/nope", headers=auth), 404, "job_not_found")
    assert_error(client.get("/calibrations/nope", headers=auth), 404, "calibration_not_found")
    assert_error(client.get("/calibrations/nope/overlay.png", headers=auth), 404)
    assert_error(client.get("/courts/nope", headers=auth), 404, "court_not_found")
    assert_error(client.get("/no/such/route"), 404, "not_found")
    assert_error(client.delete("/healthz"), 405)


@pytest.mark.parametrize(
    "raw",
    [
        '{"court_id": "C", "pixels": [[NaN, 1]]}',
        '{"court_id": "C", "pixels": [[1, Infinity]]}',
        '{"court_id": "C", "pixels": [[1, -Infinity]]}',
        '{"court_id": "C", "pixels": [[1e400, 1]]}',
        '{"court_id": "C", "pixels": [[1, 2, 3]]}',
        '{"court_id": "C", "pixels": [[1]]}',
        '{"court_id": "C", "pixels": [["a", 1]]}',
        '{"court_id": "C", "pixels": 5}',
        '{"pixels": [[1, 2]]}',
    ],
)
def test_project_rejects_bad_numbers_and_shapes(
    client: httpx.Client, auth: dict[str, str], raw: str
) -> None:
    court_id = make_court(client, auth)
    response = client.post(
        "/project",
        content=raw.replace('"C"', f'"{court_id}"').encode(),
        headers={**auth, "content-type": "application/json"},
    )
    assert_error(response, 422, "invalid_request")


def test_project_rejects_more_than_100000_points(
    client: httpx.Client, auth: dict[str, str]
) -> None:
    court_id = make_court(client, auth)
    body = {"court_id": court_id, "pixels": [[1.0, 2.0]] * 100_001}
    assert_error(client.post("/project", json=body, headers=auth), 422)


def test_an_answer_before_the_body_was_read_closes_the_connection(
    client: httpx.Client, auth: dict[str, str]
) -> None:
    # otherwise the server reads the rest of a refused body to discard it (test_live_uploads)
    response = client.post("/courts/nope/calibrations", files=[("files", ("a", b"x" * 999))])
    assert_error(response, 401)
    assert response.headers["connection"] == "close"
    # a body read to its end, or none: the connection is kept for the next request
    created = client.post("/courts", json={"name": "kept"}, headers=auth)
    assert created.status_code == 201 and "connection" not in created.headers
    assert "connection" not in client.get("/courts", headers=auth).headers


def test_openapi_documents_the_api(client: httpx.Client) -> None:
    spec = client.get("/openapi.json").json()
    paths = set(spec["paths"])
    for path in (
        "/courts",
        "/courts/{court_id}",
        "/courts/{court_id}/calibrations",
        "/courts/{court_id}/camera",
        "/courts/{court_id}/image-points",
        "/jobs/{job_id}",
        "/calibrations/{calibration_id}",
        "/calibrations/{calibration_id}/background.png",
        "/calibrations/{calibration_id}/overlay.png",
        "/project",
        "/healthz",
        "/readyz",
    ):
        assert path in paths
    upload = spec["paths"]["/courts/{court_id}/calibrations"]["post"]
    assert "multipart/form-data" in upload["requestBody"]["content"]
    assert client.get("/docs").status_code == 200
    assert client.get("/").status_code == 200


def test_ready_fails_when_the_database_is_unreachable(tmp_path) -> None:
    settings = make_settings(
        tmp_path / "d", database_url="postgresql+psycopg://postgres@127.0.0.1:1/none"
    )
    with api_client(create_app(settings)) as client:
        assert client.get("/healthz").status_code == 200
        assert_error(client.get("/readyz"), 503, "database_unreachable")
        # a request needing the database fails cleanly too (no key can be checked)
        response = client.get("/courts", headers={"Authorization": "Bearer x"})
        assert_error(response, 503, "database_unavailable")
        assert response.headers["retry-after"] == "2"

"""Hostile input: a corpus of bad requests, each with the status and error code it must get.

Every case runs against a fresh API and database; none may get a 5xx, and none may leave a job or
media behind. Cases that need more than one request (revocation, paging) are separate tests below.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest

from app.db import repo
from app.db.migrate import upgrade_head
from app.db.session import make_engine, make_sessionmaker
from app.main import create_app
from app.settings import Settings
from tests.service.conftest import api_client, make_settings, new_key
from tests.service.helpers import files, png_bytes
from tests.service.test_api import assert_error, make_court
from tests.service.test_uploads import jobs_in_db, stored_job_dirs

MAX_UPLOAD_BYTES = 2_000_000
MAX_JSON_BODY_BYTES = 4_000_000


@dataclass
class Target:
    """What a case can aim at: a court of its own tenant and one of another tenant."""

    client: httpx.Client
    auth: dict[str, str]
    court_id: str
    other_court_id: str
    tmp_path: Path

    def upload(self, parts: object, data: dict[str, str] | None = None) -> httpx.Response:
        return self.client.post(
            f"/courts/{self.court_id}/calibrations", files=parts, data=data, headers=self.auth
        )

    def raw_upload(self, body: bytes, content_type: str) -> httpx.Response:
        return self.client.post(
            f"/courts/{self.court_id}/calibrations",
            content=body,
            headers={**self.auth, "content-type": content_type},
        )

    def post_json_bytes(self, path: str, body: bytes) -> httpx.Response:
        return self.client.post(
            path, content=body, headers={**self.auth, "content-type": "application/json"}
        )


@pytest.fixture
def hostile_settings(tmp_path: Path) -> Settings:
    settings = make_settings(
        tmp_path / "data",
        max_upload_bytes=MAX_UPLOAD_BYTES,
        max_json_body_bytes=MAX_JSON_BODY_BYTES,
    )
    upgrade_head(settings)
    return settings


@pytest.fixture
def target(hostile_settings: Settings, tmp_path: Path) -> Iterator[Target]:
    auth = {"Authorization": f"Bearer {new_key(hostile_settings, 'tenant-a')}"}
    other = {"Authorization": f"Bearer {new_key(hostile_settings, 'tenant-b')}"}
    with api_client(create_app(hostile_settings)) as client:
        yield Target(client, auth, make_court(client, auth), make_court(client, other), tmp_path)


def _multipart(boundary: str, disposition: str, content: bytes) -> bytes:
    return (
        f"--{boundary}\r\nContent-Disposition: {disposition}\r\n\r\n".encode()
        + content
        + f"\r\n--{boundary}--\r\n".encode()
    )


def _long_boundary(t: Target) -> httpx.Response:
    boundary = "a" * 5000
    body = _multipart(boundary, 'form-data; name="files"; filename="a.png"', png_bytes())
    return t.raw_upload(body, f"multipart/form-data; boundary={boundary}")


def _deep_start_camera(t: Target) -> httpx.Response:
    deep = "[" * 30_000 + "]" * 30_000
    return t.upload(files(png_bytes()), data={"start_camera": deep})


def _huge_json_declared(t: Target) -> httpx.Response:
    body = b'{"court_id": "x", "pixels": [' + b"[1.0, 2.0], " * 500_000 + b"[1, 2]]}"
    return t.post_json_bytes("/project", body)


def _huge_json_streamed(t: Target) -> httpx.Response:
    """No Content-Length: the limit must hold while the body is read."""

    def chunks() -> Iterator[bytes]:
        yield b'{"court_id": "x", "pixels": ['
        for _ in range(100):
            yield b"[1.0, 2.0], " * 5_000
        yield b"[1, 2]]}"

    return t.client.post(
        "/project", content=chunks(), headers={**t.auth, "content-type": "application/json"}
    )


def _deep_json_camera_import(t: Target) -> httpx.Response:
    body = b'{"camera": ' + b"[" * 30_000 + b"]" * 30_000 + b"}"
    return t.post_json_bytes(f"/courts/{t.court_id}/camera", body)


@dataclass(frozen=True)
class Case:
    name: str
    send: Callable[[Target], httpx.Response]
    status: int
    code: str


CORPUS = [
    Case("multipart boundary of 5000 characters", _long_boundary, 422, "invalid_multipart"),
    Case("start_camera nested 30 000 deep", _deep_start_camera, 422, "invalid_start_camera"),
    Case("JSON body over the limit (declared)", _huge_json_declared, 413, "body_too_large"),
    Case("JSON body over the limit (streamed)", _huge_json_streamed, 413, "body_too_large"),
    Case("JSON nested 30 000 deep", _deep_json_camera_import, 400, "bad_request"),
]


@pytest.mark.parametrize("case", CORPUS, ids=[c.name for c in CORPUS])
def test_bad_request_is_refused(case: Case, target: Target, hostile_settings: Settings) -> None:
    response = case.send(target)
    assert_error(response, case.status, case.code)
    assert jobs_in_db(hostile_settings) == []
    assert stored_job_dirs(hostile_settings) == []


def test_revoked_key_is_refused_at_once_by_every_api_process(hostile_settings: Settings) -> None:
    engine = make_engine(hostile_settings)
    with make_sessionmaker(engine).begin() as session:
        row, key = repo.create_api_key(session, name="soon revoked")
    headers = {"Authorization": f"Bearer {key}"}
    # two API processes' worth of state, both having just accepted the key
    with (
        api_client(create_app(hostile_settings)) as first,
        api_client(create_app(hostile_settings)) as second,
    ):
        assert first.get("/courts", headers=headers).status_code == 200
        assert second.get("/courts", headers=headers).status_code == 200
        with make_sessionmaker(engine).begin() as session:
            assert repo.revoke_api_key(session, row.id)
        for client in (first, second):
            assert_error(client.get("/courts", headers=headers), 401, "unauthorized")
    engine.dispose()


def test_courts_are_listed_a_page_at_a_time(target: Target) -> None:
    t = target
    for i in range(4):
        make_court(t.client, t.auth, f"extra {i}")
    seen: list[str] = []
    offset: int | None = 0
    while offset is not None:
        page = t.client.get(f"/courts?limit=2&offset={offset}", headers=t.auth).json()
        assert len(page["courts"]) <= 2
        seen += [c["id"] for c in page["courts"]]
        offset = page["next_offset"]
    assert len(seen) == len(set(seen)) == 5  # the fixture's court and 4 more, none twice
    assert t.other_court_id not in seen
    for bad in ("limit=0", "limit=501", "offset=-1", "offset=99999999999999999999", "limit=x"):
        assert_error(t.client.get(f"/courts?{bad}", headers=t.auth), 422, "invalid_request")

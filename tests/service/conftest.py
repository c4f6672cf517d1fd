"""Fixtures for the service tests: a migrated temporary database and an in-process API client.

The database is a SQLite file of the test's own, and also (marked `postgres`) a throwaway
PostgreSQL schema for the tests marked `both_databases` (see `pytest_generate_tests`).

The client drives the real ASGI app (with its lifespan, so the camera cache refresher runs) on an
event loop in a background thread, through httpx's ASGI transport, behind a plain synchronous
httpx.Client.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

import httpx
import pytest
import sqlalchemy as sa
from fastapi import FastAPI

from app.db import repo
from app.db.migrate import upgrade_head
from app.db.session import make_engine, make_sessionmaker
from app.main import create_app
from app.settings import Settings


class _LoopThread:
    def __init__(self) -> None:
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()

    def run(self, coro, timeout: float = 120.0):  # type: ignore[no-untyped-def]
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout)

    def close(self) -> None:
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(5)
        self.loop.close()


class _SyncASGITransport(httpx.BaseTransport):
    def __init__(self, app: FastAPI, loop: _LoopThread) -> None:
        self.inner = httpx.ASGITransport(app=app)
        self.loop = loop

    def handle_request(self, request: httpx.Request) -> httpx.Response:
        body = request.read()

        async def send() -> tuple[int, httpx.Headers, bytes]:
            forwarded = httpx.Request(
                request.method, request.url, headers=request.headers, content=body
            )
            response = await self.inner.handle_async_request(forwarded)
            content = await response.aread()
            return response.status_code, response.headers, content

        status, headers, content = self.loop.run(send())
        return httpx.Response(status, headers=headers, content=content, request=request)


@contextlib.contextmanager
def api_client(app: FastAPI) -> Iterator[httpx.Client]:
    loop = _LoopThread()
    lifespan = app.router.lifespan_context(app)
    loop.run(lifespan.__aenter__())
    try:
        with httpx.Client(
            transport=_SyncASGITransport(app, loop), base_url="http://testserver"
        ) as client:
            yield client
    finally:
        loop.run(lifespan.__aexit__(None, None, None))
        loop.close()


def make_settings(data_dir: Path, **overrides: object) -> Settings:
    return Settings(data_dir=data_dir, **overrides)  # type: ignore[arg-type]


def migrated_settings(data_dir: Path, database_url: str | None, **overrides: object) -> Settings:
    """Settings on `database_url` (None: SQLite in `data_dir`), migrated to the head."""
    s = make_settings(data_dir, database_url=database_url, **overrides)
    upgrade_head(s)
    return s


@pytest.fixture
def new_settings(tmp_path: Path, database_url: str | None) -> Callable[..., Settings]:
    """Migrated settings with the test's own overrides, on the test's database (`backend`)."""

    def make(**overrides: object) -> Settings:
        return migrated_settings(tmp_path / "data", database_url, **overrides)

    return make


@pytest.fixture
def settings(new_settings: Callable[..., Settings]) -> Settings:
    return new_settings(camera_refresh_s=0.05)


@pytest.fixture
def client(settings: Settings) -> Iterator[httpx.Client]:
    with api_client(create_app(settings)) as c:
        yield c


def new_key(settings: Settings, name: str = "tester") -> str:
    engine = make_engine(settings)
    try:
        with make_sessionmaker(engine).begin() as session:
            _, key = repo.create_api_key(session, name=name)
        return key
    finally:
        engine.dispose()


@pytest.fixture
def auth(settings: Settings) -> dict[str, str]:
    return {"Authorization": f"Bearer {new_key(settings, 'tenant-a')}"}


@pytest.fixture
def other_auth(settings: Settings) -> dict[str, str]:
    return {"Authorization": f"Bearer {new_key(settings, 'tenant-b')}"}


POSTGRES_ADMIN_URL = "postgresql+psycopg://postgres@127.0.0.1:5432/test"


def _postgres_reachable() -> str | None:
    """None if the test PostgreSQL answers, else why not."""
    import sqlalchemy as sa

    engine = sa.create_engine(POSTGRES_ADMIN_URL, connect_args={"connect_timeout": 3})
    try:
        with engine.connect() as conn:
            conn.execute(sa.text("SELECT 1"))
        return None
    except Exception as exc:
        return f"PostgreSQL at 127.0.0.1:5432/test unreachable: {type(exc).__name__}: {exc}"
    finally:
        engine.dispose()


@contextlib.contextmanager
def postgres_schema() -> Iterator[str]:
    """A fresh schema for this test, dropped afterwards; yields a DATABASE_URL that uses it."""
    import uuid

    import sqlalchemy as sa

    reason = _postgres_reachable()
    if reason is not None:
        # CI (.ci/run) starts the server and asks for these tests to run, not to skip quietly
        if os.environ.get("SQUASHCAL_REQUIRE_POSTGRES") == "1":
            pytest.fail(reason)
        pytest.skip(reason)
    schema = f"squashcal_test_{uuid.uuid4().hex[:12]}"
    # pre-ping: a test may restart the server, and the schema must still be dropped afterwards
    admin = sa.create_engine(POSTGRES_ADMIN_URL, pool_pre_ping=True)
    with admin.begin() as conn:
        conn.execute(sa.text(f'CREATE SCHEMA "{schema}"'))
    try:
        yield f"{POSTGRES_ADMIN_URL}?options=-csearch_path%3D{schema}"
    finally:
        with admin.begin() as conn:
            conn.execute(sa.text(f'DROP SCHEMA "{schema}" CASCADE'))
        admin.dispose()


@contextlib.contextmanager
def database_url_for(backend: str) -> Iterator[str | None]:
    """None for SQLite (a file in the data dir), else a throwaway PostgreSQL schema's URL."""
    if backend == "sqlite":
        yield None
        return
    with postgres_schema() as url:
        yield url


BACKENDS = ["sqlite", pytest.param("postgres", marks=pytest.mark.postgres)]


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    # issue 8: the API, queue and worker suites hold on both databases. A test (or a module, by
    # `pytestmark`) marked `both_databases` runs once per backend when it uses a database through
    # these fixtures; other tests stay on SQLite, and tests without a database run once.
    if "backend" in metafunc.fixturenames and metafunc.definition.get_closest_marker(
        "both_databases"
    ):
        metafunc.parametrize("backend", BACKENDS, indirect=True)


@pytest.fixture(scope="module")
def backend(request: pytest.FixtureRequest) -> str:
    """The test's database backend: SQLite unless the test is marked `both_databases`.
    Module-scoped, so that a module's shared fixtures (test_page_api's calibration) can use it."""
    return str(getattr(request, "param", "sqlite"))


@pytest.fixture
def database_url(backend: str) -> Iterator[str | None]:
    """The test's own database: a fresh SQLite file or PostgreSQL schema, see `database_url_for`."""
    with database_url_for(backend) as url:
        yield url


@pytest.fixture(params=BACKENDS)
def any_db_settings(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Settings]:
    """Migrated settings on SQLite and (marked `postgres`) on a throwaway PostgreSQL schema."""
    with database_url_for(request.param) as url:
        yield migrated_settings(tmp_path / "data", url)


@pytest.fixture
def engine(any_db_settings: Settings) -> Iterator[sa.Engine]:
    """An engine on `any_db_settings`' database (both backends)."""
    eng = make_engine(any_db_settings)
    yield eng
    eng.dispose()

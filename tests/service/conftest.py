"""Fixtures for the service tests: a migrated temporary database and an in-process API client.

The client drives the real ASGI app (with its lifespan, so the camera cache refresher runs) on an
event loop in a background thread, through httpx's ASGI transport, behind a plain synchronous
httpx.Client.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
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


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    s = make_settings(tmp_path / "data", camera_refresh_s=0.05, auth_cache_s=0.0)
    upgrade_head(s)
    return s


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

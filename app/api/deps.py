"""Shared state of one API process and the dependencies handlers declare."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Annotated

from anyio import to_thread
from fastapi import Depends, Request
from fastapi.security import HTTPBearer
from sqlalchemy import Engine
from sqlalchemy.orm import Session, sessionmaker

from app.api.camera_cache import CameraCache
from app.api.errors import ApiError
from app.db import repo
from app.settings import Settings


@dataclass
class AppState:
    settings: Settings
    engine: Engine
    sessions: sessionmaker[Session]
    # for transactions that write after reading: on SQLite they take the write lock at BEGIN,
    # since a reading transaction cannot take it once another connection has committed since
    # its snapshot (SQLite answers "database is locked" at once, whatever the busy timeout)
    write_sessions: sessionmaker[Session]
    cameras: CameraCache
    keys: repo.KeyLookup
    head_revision: str | None
    # set once the numerical kernels are compiled or loaded (`app.calib.warmup`); /readyz waits
    kernels_ready: threading.Event = field(default_factory=threading.Event)


# Dependencies that do no blocking work are `async def`: FastAPI runs a plain `def` dependency in
# its thread pool, and on the /project path each such hop cost more than the work itself.


async def get_state(request: Request) -> AppState:
    state: AppState = request.app.state.squashcal
    return state


StateDep = Annotated[AppState, Depends(get_state)]


def get_session(state: StateDep) -> Iterator[Session]:
    with state.sessions() as session:
        yield session


SessionDep = Annotated[Session, Depends(get_session)]


def get_write_session(state: StateDep) -> Iterator[Session]:
    with state.write_sessions() as session:
        yield session


WriteSessionDep = Annotated[Session, Depends(get_write_session)]

_UNAUTHORIZED_HEADERS = {"WWW-Authenticate": "Bearer"}


@dataclass(frozen=True)
class Caller:
    """An authenticated request's tenant, with the process's state."""

    state: AppState
    tenant_id: str


class ApiKeyAuth(HTTPBearer):
    """`Authorization: Bearer KEY` -> the caller's tenant (a Caller), as ONE dependency.

    It is FastAPI's HTTPBearer (so the OpenAPI document declares the same `HTTPBearer` scheme)
    that also looks the key up: each dependency FastAPI resolves costs microseconds on every
    request, and /project's budget is counted in them.

    Looked up on every request, on purpose: a revoked key must be refused at once by every API
    process, and no cache can promise that without a message from the database. The lookup is one
    indexed read of a unique column (a few us on SQLite, one round trip on PostgreSQL): see
    `repo.KeyLookup`. On SQLite (a local file, no network) it runs on the event loop: handing it
    to a thread costs more than the read (and under load the GIL hand-over adds milliseconds of
    tail latency). A networked database's round trip goes to a thread, so that a slow database
    never stalls the loop.
    """

    async def __call__(self, request: Request) -> Caller:  # type: ignore[override]
        credentials = await super().__call__(request)
        if credentials is None or not credentials.credentials:
            raise ApiError(
                401,
                "unauthorized",
                "missing API key: send 'Authorization: Bearer <key>'",
                _UNAUTHORIZED_HEADERS,
            )
        state: AppState = request.app.state.squashcal
        if state.keys.local:
            tenant_id = state.keys.tenant_for(credentials.credentials)
        else:
            tenant_id = await to_thread.run_sync(state.keys.tenant_for, credentials.credentials)
        if tenant_id is None:
            raise ApiError(401, "unauthorized", "invalid or revoked API key", _UNAUTHORIZED_HEADERS)
        return Caller(state, tenant_id)


get_caller = ApiKeyAuth(
    auto_error=False,
    description="an API key from `squashcal keys create`",
    scheme_name="HTTPBearer",
)

CallerDep = Annotated[Caller, Depends(get_caller)]


async def get_tenant(caller: CallerDep) -> str:
    """The caller's tenant id (`get_caller`)."""
    return caller.tenant_id


TenantDep = Annotated[str, Depends(get_tenant)]

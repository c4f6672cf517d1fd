"""Shared state of one API process and the dependencies handlers declare."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Annotated

from fastapi import Depends, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from sqlalchemy import Engine
from sqlalchemy.orm import Session, sessionmaker

from app.api.camera_cache import AuthCache, CameraCache
from app.api.errors import ApiError
from app.db import repo
from app.settings import Settings


@dataclass
class AppState:
    settings: Settings
    engine: Engine
    sessions: sessionmaker[Session]
    cameras: CameraCache
    auth: AuthCache
    head_revision: str | None
    # set once the numerical kernels are compiled or loaded (`app.calib.warmup`); /readyz waits
    kernels_ready: threading.Event = field(default_factory=threading.Event)


def get_state(request: Request) -> AppState:
    state: AppState = request.app.state.squashcal
    return state


StateDep = Annotated[AppState, Depends(get_state)]


def get_session(state: StateDep) -> Iterator[Session]:
    with state.sessions() as session:
        yield session


SessionDep = Annotated[Session, Depends(get_session)]

_bearer = HTTPBearer(auto_error=False, description="an API key from `squashcal keys create`")
_UNAUTHORIZED_HEADERS = {"WWW-Authenticate": "Bearer"}


def get_tenant(
    state: StateDep,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
) -> str:
    """The caller's tenant id from `Authorization: Bearer KEY` (cached: no database on a hit)."""
    if credentials is None or not credentials.credentials:
        raise ApiError(
            401,
            "unauthorized",
            "missing API key: send 'Authorization: Bearer <key>'",
            _UNAUTHORIZED_HEADERS,
        )
    key_hash = repo.hash_key(credentials.credentials)
    tenant_id = state.auth.get(key_hash)
    if tenant_id is None:
        with state.sessions() as session:
            tenant_id = repo.tenant_for_key_hash(session, key_hash)
        if tenant_id is None:
            raise ApiError(401, "unauthorized", "invalid or revoked API key", _UNAUTHORIZED_HEADERS)
        state.auth.put(key_hash, tenant_id)
    return tenant_id


TenantDep = Annotated[str, Depends(get_tenant)]

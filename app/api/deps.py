"""Shared state of one API process and the dependencies handlers declare."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Annotated, Any

from fastapi import Depends, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
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
    cameras: CameraCache
    keys: repo.KeyLookup
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
    """The caller's tenant id from `Authorization: Bearer KEY`.

    Looked up on every request, on purpose: a revoked key must be refused at once by every API
    process, and no cache can promise that without a message from the database. The lookup is one
    indexed read of a unique column (~45 us on SQLite, one round trip on PostgreSQL): see
    `repo.KeyLookup`.
    """
    if credentials is None or not credentials.credentials:
        raise ApiError(
            401,
            "unauthorized",
            "missing API key: send 'Authorization: Bearer <key>'",
            _UNAUTHORIZED_HEADERS,
        )
    tenant_id = state.keys.tenant_for(credentials.credentials)
    if tenant_id is None:
        raise ApiError(401, "unauthorized", "invalid or revoked API key", _UNAUTHORIZED_HEADERS)
    return tenant_id


TenantDep = Annotated[str, Depends(get_tenant)]


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

"""The FastAPI application factory."""

from __future__ import annotations

import asyncio
import contextlib
import gc
import logging
import threading
from collections.abc import AsyncIterator

from fastapi import FastAPI
from sqlalchemy.orm import Session, sessionmaker

from app.api import api_router
from app.api.body_limit import BodyLimitMiddleware
from app.api.camera_cache import CameraCache
from app.api.deps import AppState
from app.api.errors import install_error_handlers
from app.api.openapi import install_openapi
from app.api.security_headers import SecurityHeadersMiddleware
from app.api.unread_body import CloseOnUnreadBodyMiddleware
from app.db import repo
from app.db.migrate import head_revision
from app.db.session import make_engine, make_sessionmaker, write_engine
from app.media.store import media_store
from app.media.sweep import sweep_quietly
from app.schemas import ErrorResponse, ProjectRequest
from app.settings import Settings, get_settings

log = logging.getLogger("squashcal.api")


async def _sweep_media_forever(settings: Settings, sessions: sessionmaker[Session]) -> None:
    """Sweep stored media at start (orphans of a crash) and then every interval."""
    store = media_store(settings)
    while True:
        await asyncio.to_thread(sweep_quietly, store, sessions, settings)
        await asyncio.sleep(settings.media_sweep_interval_s)


def component_schemas() -> dict[str, object]:
    """OpenAPI component schemas FastAPI does not derive from the routes: ErrorResponse and
    ErrorDetail, and the bodies read by `app.api.json_body` (ProjectRequest)."""
    from pydantic.json_schema import models_json_schema

    _, top = models_json_schema(
        [(ErrorResponse, "serialization"), (ProjectRequest, "validation")],
        ref_template="#/components/schemas/{model}",
    )
    return dict(top["$defs"])


def create_app(settings: Settings | None = None, warm_up: bool = False) -> FastAPI:
    """The API. `warm_up`: load the numerical kernels in a thread at start, /readyz saying 503
    `warming_up` until they are (`squashcal serve` does; in-process test apps need not)."""
    settings = settings or get_settings()
    engine = make_engine(settings)
    sessions = make_sessionmaker(engine)
    state = AppState(
        settings=settings,
        engine=engine,
        sessions=sessions,
        write_sessions=make_sessionmaker(write_engine(engine)),
        cameras=CameraCache(sessions, settings.camera_refresh_s, settings.camera_cache_size),
        keys=repo.KeyLookup(engine),
        head_revision=head_revision(settings),
    )

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        refresher = asyncio.create_task(state.cameras.run_refresher())
        sweeper = asyncio.create_task(_sweep_media_forever(settings, sessions))
        if warm_up:
            # a thread, not the event loop: /healthz answers while the kernels load
            threading.Thread(
                target=_warm_kernels, args=(state,), name="warm-up", daemon=True
            ).start()
        else:
            state.kernels_ready.set()
        _freeze_startup_objects()
        try:
            yield
        finally:
            for task in (refresher, sweeper):
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await task
            # a refresh already running in its thread outlives the cancelled task: let it end
            await asyncio.to_thread(state.cameras.wait_idle)
            state.keys.close()
            engine.dispose()

    app = FastAPI(
        title="squashcal",
        version="0.1.0",
        summary="Squash court camera calibration: upload frames or a clip, get a camera, map "
        "pixels to court metres.",
        lifespan=lifespan,
        # served locally by app.api.docs, not from a public CDN
        docs_url=None,
        redoc_url=None,
    )
    app.state.squashcal = state
    install_error_handlers(app)
    app.add_middleware(BodyLimitMiddleware, max_bytes=settings.max_json_body_bytes)
    app.add_middleware(SecurityHeadersMiddleware)
    # outermost: it must see the body as the server delivers it, and every response's headers
    app.add_middleware(CloseOnUnreadBodyMiddleware)
    app.include_router(api_router)
    install_openapi(app, component_schemas())
    return app


def served_app() -> FastAPI:
    """The app `squashcal serve` runs in each API process: settings from the environment, the
    kernels loaded at start (unless SQUASHCAL_WARM_UP=0)."""
    settings = get_settings()
    return create_app(settings, warm_up=settings.warm_up)


def _freeze_startup_objects() -> None:
    """Move every object alive now (modules, the app, compiled kernels: ~200 000 of them, kept
    for the life of the process) out of the garbage collector's sight. Without this each full
    collection walks them all: a request that creates a few thousand lists (1000 points) then
    costs about twice its own work in collections."""
    gc.collect()
    gc.freeze()


def _warm_kernels(state: AppState) -> None:
    from app.calib import warmup

    warmup.warm_up_best_effort(warmup.API_PARTS)
    _freeze_startup_objects()  # the kernels' objects too
    state.kernels_ready.set()

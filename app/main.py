"""The FastAPI application factory."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
from collections.abc import AsyncIterator

from fastapi import FastAPI

from app.api import api_router
from app.api.camera_cache import AuthCache, CameraCache
from app.api.deps import AppState
from app.api.errors import install_error_handlers
from app.db.migrate import head_revision
from app.db.session import make_engine, make_sessionmaker
from app.settings import Settings, get_settings

log = logging.getLogger("squashcal.api")


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
        cameras=CameraCache(sessions, settings.camera_refresh_s, settings.camera_cache_size),
        auth=AuthCache(settings.auth_cache_s),
        head_revision=head_revision(settings),
    )

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        refresher = asyncio.create_task(state.cameras.run_refresher())
        if warm_up:
            # a thread, not the event loop: /healthz answers while the kernels load
            threading.Thread(
                target=_warm_kernels, args=(state,), name="warm-up", daemon=True
            ).start()
        else:
            state.kernels_ready.set()
        try:
            yield
        finally:
            refresher.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await refresher
            # a refresh already running in its thread outlives the cancelled task: let it end
            await asyncio.to_thread(state.cameras.wait_idle)
            engine.dispose()

    app = FastAPI(
        title="squashcal",
        version="0.1.0",
        summary="Squash court camera calibration: upload frames or a clip, get a camera, map "
        "pixels to court metres.",
        lifespan=lifespan,
    )
    app.state.squashcal = state
    install_error_handlers(app)
    app.include_router(api_router)
    return app


def _warm_kernels(state: AppState) -> None:
    from app.calib import warmup

    warmup.warm_up_best_effort(warmup.API_PARTS)
    state.kernels_ready.set()

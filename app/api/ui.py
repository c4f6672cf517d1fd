"""The browser page: index.html, its script, style and icon (from app/static/), and the little
it needs to know before it talks to the API."""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter
from fastapi.responses import FileResponse

from app.api.deps import StateDep
from app.api.errors import ApiError
from app.api.routing import ApiRoute
from app.api.security_headers import PAGE_CSP
from app.calib.court import COURT_SPECS
from app.media.sniff import IMAGE_TYPES, VIDEO_TYPES
from app.schemas import PageConfig

STATIC_DIR = Path(__file__).resolve().parents[1] / "static"
STATIC_TYPES = {
    ".js": "text/javascript",
    ".css": "text/css",
    ".svg": "image/svg+xml",
    ".html": "text/html",
}

router = APIRouter(include_in_schema=False, route_class=ApiRoute)


@router.get("/")
def index() -> FileResponse:
    return FileResponse(
        STATIC_DIR / "index.html",
        media_type="text/html",
        headers={"Content-Security-Policy": PAGE_CSP},
    )


@router.get("/static/{name}")
def static_file(name: str) -> FileResponse:
    """One file directly in app/static/ (no sub-folders, no path tricks)."""
    path = STATIC_DIR / name
    media_type = STATIC_TYPES.get(path.suffix)
    if media_type is None or "/" in name or name.startswith(".") or not path.is_file():
        raise ApiError(404, "not_found", f"no static file {name!r}")
    return FileResponse(path, media_type=media_type, headers={"Cache-Control": "no-cache"})


@router.get("/favicon.ico")
def favicon() -> FileResponse:
    return FileResponse(STATIC_DIR / "favicon.svg", media_type="image/svg+xml")


@router.get("/ui/config", response_model=PageConfig)
def page_config(state: StateDep) -> PageConfig:
    """Court specs and upload limits, so the page can check files before sending them."""
    return PageConfig(
        specs=[{"name": s.name, "description": s.description} for s in COURT_SPECS.values()],
        max_upload_bytes=state.settings.max_upload_bytes,
        max_files=state.settings.max_files,
        image_types=list(IMAGE_TYPES),
        video_types=list(VIDEO_TYPES),
    )

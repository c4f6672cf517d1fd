"""A demo clip made by the project's own renderer, so a visitor without footage sees the product
work: the page fetches it and uploads it through the normal calibration flow."""

from __future__ import annotations

import os
import uuid
from pathlib import Path

from fastapi import APIRouter
from fastapi.responses import FileResponse
from starlette.concurrency import run_in_threadpool

from app.api.deps import StateDep, TenantDep
from app.api.routing import ApiRoute
from app.calib import scene, synthetic
from app.schemas import ErrorResponse

router = APIRouter(tags=["demo"], route_class=ApiRoute)

DEMO_SIZE = (1280, 720)
DEMO_FRAMES = 40
DEMO_SEED = 7
DEMO_VERSION = 1  # bump when the renderer's output should be made anew


def demo_clip_path(media_dir: Path) -> Path:
    """The demo clip, rendered once and kept (written to a temporary name, then renamed)."""
    path = media_dir / "demo" / f"demo-v{DEMO_VERSION}-{DEMO_SIZE[0]}x{DEMO_SIZE[1]}.mp4"
    if path.is_file():
        return path
    path.parent.mkdir(parents=True, exist_ok=True)
    genome = synthetic.typical_target_camera(DEMO_SIZE)
    frames = scene.render_clip_frames(genome, DEMO_SIZE, DEMO_FRAMES, DEMO_SEED, n_players=2)
    partial = path.with_name(f".{uuid.uuid4().hex}.mp4")
    try:
        scene.write_video(frames, partial)
        os.replace(partial, path)
    finally:
        partial.unlink(missing_ok=True)
    return path


@router.get(
    "/demo/clip.mp4",
    response_class=FileResponse,
    responses={200: {"content": {"video/mp4": {}}}, 401: {"model": ErrorResponse}},
)
async def demo_clip(state: StateDep, tenant_id: TenantDep) -> FileResponse:
    """A 1.6 s synthetic clip of a squash court with two players (1280x720, MPEG-4), rendered by
    the service's own court renderer; upload it to a court to try the service without footage."""
    path = await run_in_threadpool(demo_clip_path, state.settings.media_dir)
    return FileResponse(path, media_type="video/mp4", filename="squashcal-demo.mp4")

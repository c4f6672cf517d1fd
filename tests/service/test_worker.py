"""The worker in-process with the real pipeline: success, camera cache refresh, failures."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import httpx
import numpy as np
import pytest
from sqlalchemy import select

from app import media
from app.calib import camera, scene, synthetic
from app.db import queue
from app.db.models import Calibration
from app.db.session import make_engine, make_sessionmaker
from app.main import create_app
from app.settings import Settings
from tests import clips
from tests.service.conftest import api_client, new_key
from tests.service.helpers import court_clip_bytes, files
from tests.service.test_api import assert_error, make_court
from worker.main import Shutdown, clip_background, process_job

SIZE = (960, 540)
MID_COURT_M = np.array([[3.2, 5.44], [2.0, 4.5], [4.4, 6.5], [3.2, 7.5]])

pytestmark = pytest.mark.both_databases


def run_one_job(settings: Settings) -> str:
    engine = make_engine(settings)
    try:
        job = queue.claim(engine, "test-worker", settings.lease_s)
        assert job is not None
        return process_job(engine, settings, job, "test-worker", Shutdown(threading.Event()))
    finally:
        engine.dispose()


@pytest.fixture
def worker_settings(new_settings: Callable[..., Settings]) -> Settings:
    return new_settings(camera_refresh_s=0.05, background_frames=7, progress_interval_s=0.1)


def png_frames(genome: np.ndarray, n: int, seed: int) -> list[bytes]:
    frames = scene.render_clip_frames(genome, SIZE, n, seed, n_players=2)
    return [cv2.imencode(".png", f)[1].tobytes() for f in frames]


def wait_for_calibration(
    client: httpx.Client, auth: dict[str, str], court_id: str, calibration_id: str
) -> dict:
    deadline = time.monotonic() + 10
    while True:
        body = client.post(
            "/project", json={"court_id": court_id, "pixels": [[480, 300]]}, headers=auth
        ).json()
        if body.get("calibration_id") == calibration_id or time.monotonic() > deadline:
            return body
        time.sleep(0.02)


def test_calibrations_replace_the_cached_camera(worker_settings: Settings, tmp_path: Path) -> None:
    auth = {"Authorization": f"Bearer {new_key(worker_settings)}"}
    camera_a = synthetic.typical_target_camera(SIZE)
    camera_b = camera_a.copy()
    camera_b[camera.GENE["t_x"]] += 0.6  # the camera moved 60 cm sideways and turned a little
    camera_b[camera.GENE["beta"]] -= 0.04
    with api_client(create_app(worker_settings)) as client:
        court_id = make_court(client, auth)
        clip = court_clip_bytes(tmp_path, camera_a, SIZE, 12, seed=1)
        job_a = client.post(
            f"/courts/{court_id}/calibrations", files=files(clip), headers=auth
        ).json()["job_id"]
        assert run_one_job(worker_settings) == "succeeded"
        job = client.get(f"/jobs/{job_a}", headers=auth).json()
        assert job["status"] == "succeeded" and job["progress"] == 1.0 and job["error"] is None
        # no GA bundle asked for: the product finds the camera without generations
        assert job["stage"] == "done" and job["generation"] is None
        assert {"background", "calibrate", "storing", "total"} <= set(job["timings_s"])
        cal_a = job["calibration_id"]

        pixels_a = camera.floor_to_pixel(camera_a, MID_COURT_M)
        assert wait_for_calibration(client, auth, court_id, cal_a)["calibration_id"] == cal_a
        body = client.post(
            "/project", json={"court_id": court_id, "pixels": pixels_a.tolist()}, headers=auth
        ).json()
        assert body["calibration_id"] == cal_a
        assert body["inside_court"] == [True] * len(MID_COURT_M)
        error_cm = 100 * np.linalg.norm(np.array(body["points"]) - MID_COURT_M, axis=1)
        assert error_cm.max() < 5.0, error_cm
        # the cache is warm now; a second calibration from images of the moved camera
        images = png_frames(camera_b, 5, seed=2)
        job_b = client.post(
            f"/courts/{court_id}/calibrations", files=files(*images), headers=auth
        ).json()["job_id"]
        assert run_one_job(worker_settings) == "succeeded"
        cal_b = client.get(f"/jobs/{job_b}", headers=auth).json()["calibration_id"]
        assert cal_b != cal_a
        body = wait_for_calibration(client, auth, court_id, cal_b)
        assert body["calibration_id"] == cal_b
        pixels_b = camera.floor_to_pixel(camera_b, MID_COURT_M)
        body = client.post(
            "/project", json={"court_id": court_id, "pixels": pixels_b.tolist()}, headers=auth
        ).json()
        error_cm = 100 * np.linalg.norm(np.array(body["points"]) - MID_COURT_M, axis=1)
        assert error_cm.max() < 5.0, error_cm
        assert np.abs(pixels_a - pixels_b).max() > 20  # the two cameras really differ

        # the inverse goes through the same cached camera
        back = client.post(
            f"/courts/{court_id}/image-points",
            json={"points": MID_COURT_M.tolist() + [[3.2, 30.0]]},
            headers=auth,
        ).json()
        assert back["calibration_id"] == cal_b
        np.testing.assert_allclose(np.array(back["pixels"][:4]), pixels_b, atol=3.0)
        assert back["in_image"][:4] == [True] * 4

        active = client.get(f"/courts/{court_id}/camera", headers=auth).json()
        assert active["id"] == cal_b and active["active"] and active["job_id"] == job_b
        assert active["opencv"]["image_size"] == list(SIZE)
        old = client.get(f"/calibrations/{cal_a}", headers=auth).json()
        assert old["id"] == cal_a and not old["active"]
        listed = client.get(f"/courts/{court_id}/calibrations", headers=auth).json()
        assert [c["id"] for c in listed["calibrations"]] == [cal_b, cal_a]
        for name in ("background.png", "overlay.png"):
            response = client.get(f"/calibrations/{cal_a}/{name}", headers=auth)
            assert response.status_code == 200
            assert response.headers["content-type"] == "image/png"
            image = cv2.imdecode(np.frombuffer(response.content, np.uint8), cv2.IMREAD_COLOR)
            assert image.shape == (SIZE[1], SIZE[0], 3)


def test_image_without_a_court_fails_as_court_not_found(
    worker_settings: Settings, tmp_path: Path
) -> None:
    auth = {"Authorization": f"Bearer {new_key(worker_settings)}"}
    rng = np.random.default_rng(0)
    image = cv2.GaussianBlur(rng.integers(0, 255, (SIZE[1], SIZE[0], 3), dtype=np.uint8), (0, 0), 3)
    for _ in range(30):  # blocks with straight edges, but no court
        x, y = (int(v) for v in rng.integers(0, [SIZE[0] - 60, SIZE[1] - 60]))
        w, h = (int(v) for v in rng.integers(20, 200, 2))
        colour = tuple(int(c) for c in rng.integers(0, 255, 3))
        cv2.rectangle(image, (x, y), (x + w, y + h), colour, -1)
    with api_client(create_app(worker_settings)) as client:
        court_id = make_court(client, auth)
        png = cv2.imencode(".png", image)[1].tobytes()
        job_id = client.post(
            f"/courts/{court_id}/calibrations", files=files(png), headers=auth
        ).json()["job_id"]
        assert run_one_job(worker_settings) == "failed"
        job = client.get(f"/jobs/{job_id}", headers=auth).json()
        assert job["status"] == "failed" and job["attempts"] == 1
        assert job["error"]["code"] == "court_not_found"
        assert "court" in job["error"]["message"]
        assert job["calibration_id"] is None
        assert_error(client.get(f"/courts/{court_id}/camera", headers=auth), 404, "no_calibration")
    assert not (worker_settings.media_dir / "calibrations").exists() or not any(
        (worker_settings.media_dir / "calibrations").iterdir()
    )


def test_lost_media_fails_with_a_specific_code(worker_settings: Settings) -> None:
    auth = {"Authorization": f"Bearer {new_key(worker_settings)}"}
    with api_client(create_app(worker_settings)) as client:
        court_id = make_court(client, auth)
        png = cv2.imencode(".png", np.zeros((48, 64, 3), np.uint8))[1].tobytes()
        job_id = client.post(
            f"/courts/{court_id}/calibrations", files=files(png), headers=auth
        ).json()["job_id"]
        for path in media.job_dir(worker_settings, job_id).iterdir():
            path.unlink()
        assert run_one_job(worker_settings) == "failed"
        job = client.get(f"/jobs/{job_id}", headers=auth).json()
        assert job["error"]["code"] == "media_missing"


def _stored_result(settings: Settings, calibration_id: str) -> dict:
    """The calibration's result JSON as the worker stored it (the API does not show all of it)."""
    engine = make_engine(settings)
    try:
        with make_sessionmaker(engine)() as session:
            calibration = session.scalars(
                select(Calibration).where(Calibration.id == calibration_id)
            ).one()
            return dict(calibration.result)
    finally:
        engine.dispose()


def _run_clip_job(
    settings: Settings,
    client: httpx.Client,
    auth: dict[str, str],
    court_id: str,
    clip: Path,
    expected_status: str,
) -> dict:
    """Upload the clip, run its job in this process; the job as the API shows it."""
    job_id = client.post(
        f"/courts/{court_id}/calibrations", files=files(clip.read_bytes()), headers=auth
    ).json()["job_id"]
    assert run_one_job(settings) == expected_status
    return client.get(f"/jobs/{job_id}", headers=auth).json()


def test_clip_with_a_cut_uses_the_main_view(worker_settings: Settings, tmp_path: Path) -> None:
    """Main camera, a close-up replay, the main camera again: the stored result says so."""
    auth = {"Authorization": f"Bearer {new_key(worker_settings)}"}
    genome = clips.main_camera(SIZE)
    main = clips.render_clip_frames(genome, SIZE, 36, 31)
    close_up = clips.render_clip_frames(clips.close_up_camera(SIZE), SIZE, 14, 32)
    path = tmp_path / "cut.mp4"
    clips.write_video(main[:20] + close_up + main[20:], path)
    with api_client(create_app(worker_settings)) as client:
        court_id = make_court(client, auth)
        job = _run_clip_job(worker_settings, client, auth, court_id, path, "succeeded")
        assert {"background.decode", "background.segmentation"} <= set(job["timings_s"])
        info = _stored_result(worker_settings, job["calibration_id"])["background"]
        # 960x540 clips are sampled every second frame: frames 0-18 and 34-48 are seen
        assert info["frame_ranges"] == [[0, 18], [34, 48]]
        assert info["cuts_s"] == [0.8, 1.36] and info["shots"] == 3
        assert info["frames_used"] == worker_settings.background_frames
        body = client.post(
            "/project",
            json={
                "court_id": court_id,
                "pixels": camera.floor_to_pixel(genome, MID_COURT_M).tolist(),
            },
            headers=auth,
        ).json()
        error_cm = 100 * np.linalg.norm(np.array(body["points"]) - MID_COURT_M, axis=1)
        assert error_cm.max() < 5.0, error_cm


def test_clip_background_keeps_frames_within_the_memory_setting(tmp_path: Path) -> None:
    """The worker's clip stage takes its frame budget from max_clip_frames_mb: 960x540 frames
    take 1.56 MB, so 19 MB hold 3 x 4 of them: 4 frames for the background instead of 7."""
    frames = clips.render_clip_frames(clips.main_camera(SIZE), SIZE, 40, 33)
    path = tmp_path / "static.mp4"
    clips.write_video(frames, path)
    _, _, info = clip_background(path, Settings(data_dir=tmp_path, background_frames=7))
    assert info["frames_used"] == 7 and not info["frames_limited_by_memory"]
    small = Settings(data_dir=tmp_path, background_frames=7, max_clip_frames_mb=19)
    _, _, limited = clip_background(path, small)
    assert limited["frames_used"] == 4 and limited["frames_limited_by_memory"]


def test_clip_without_a_static_view_fails(worker_settings: Settings, tmp_path: Path) -> None:
    auth = {"Authorization": f"Bearer {new_key(worker_settings)}"}
    court = clips.render_court_image(clips.main_camera(SIZE), SIZE, rng=33)
    path = tmp_path / "zooming.mp4"
    clips.write_video([clips.zoomed(court, 1.0 + 0.01 * i) for i in range(40)], path)
    with api_client(create_app(worker_settings)) as client:
        court_id = make_court(client, auth)
        job = _run_clip_job(worker_settings, client, auth, court_id, path, "failed")
        assert job["error"]["code"] == "no_static_view"
        assert "no static view of the court longer than" in job["error"]["message"]

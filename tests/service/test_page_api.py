"""The API behind the browser page: pictures, lines, per-calibration projection, active camera,
import, YAML export, jobs list, /me, page config, static files, demo clip.

One real calibration (synthetic clip, real pipeline through the worker's `process_job`) is made
once for the module and shared by the read-only tests.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import httpx
import numpy as np
import pytest

from app.calib import camera
from app.main import create_app
from app.settings import Settings
from tests import renderer
from tests.service.conftest import api_client, database_url_for, migrated_settings, new_key
from tests.service.helpers import court_clip_bytes, files
from tests.service.test_api import assert_error
from tests.service.test_worker import run_one_job

SIZE = (960, 540)

pytestmark = pytest.mark.both_databases


@dataclass
class Calibrated:
    settings: Settings
    client: httpx.Client
    auth: dict[str, str]
    court_id: str
    calibration: dict
    truth: np.ndarray


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory: pytest.TempPathFactory, backend: str) -> Iterator[Calibrated]:
    tmp = tmp_path_factory.mktemp("page_api")
    with database_url_for(backend) as url:
        settings = migrated_settings(
            tmp / "data", url, camera_refresh_s=0.05, background_frames=7, ga_max_generations=40
        )
        auth = {"Authorization": f"Bearer {new_key(settings, 'coach')}"}
        truth = renderer.typical_target_camera(SIZE)
        with api_client(create_app(settings)) as client:
            court_id = client.post("/courts", json={"name": "page"}, headers=auth).json()["id"]
            clip = court_clip_bytes(tmp, truth, SIZE, n_frames=20, seed=5)
            response = client.post(
                f"/courts/{court_id}/calibrations", files=files(clip), headers=auth
            )
            assert response.status_code == 202, response.text
            assert run_one_job(settings) == "succeeded"
            cal = client.get(f"/courts/{court_id}/camera", headers=auth).json()
            yield Calibrated(settings, client, auth, court_id, cal, truth)


def png(response: httpx.Response) -> np.ndarray:
    assert response.status_code == 200, response.text
    assert response.headers["content-type"] == "image/png"
    image = cv2.imdecode(np.frombuffer(response.content, np.uint8), cv2.IMREAD_COLOR)
    assert image is not None
    return image


def test_calibration_carries_pose_source_and_timings(calibrated: Calibrated) -> None:
    cal = calibrated.calibration
    assert cal["source"] == "upload" and cal["job_id"]
    pose = cal["pose"]
    # the typical camera: centred behind the back wall, ~4.7 m up, looking at the front wall
    assert pose["position_m"][0] == pytest.approx(3.2, abs=0.05)
    assert pose["height_m"] == pytest.approx(4.71, abs=0.05)
    assert pose["height_m"] == pytest.approx(-pose["position_m"][2])
    assert abs(pose["pan_deg"]) < 1 and 10 < pose["tilt_deg"] < 25 and abs(pose["roll_deg"]) < 1
    assert {"edges", "search", "refine"} <= set(cal["timings_s"])


def test_overlay_is_antialiased_and_start_camera_is_drawn(calibrated: Calibrated) -> None:
    c, auth, cal_id = calibrated.client, calibrated.auth, calibrated.calibration["id"]
    fitted = png(c.get(f"/calibrations/{cal_id}/overlay.png", headers=auth))
    assert fitted.shape == (SIZE[1], SIZE[0], 3)
    background = png(c.get(f"/calibrations/{cal_id}/background.png", headers=auth))
    changed = np.any(fitted != background, axis=2)
    assert 0.01 < changed.mean() < 0.3
    # anti-aliased: pixels between the line's green and the halo's black, not only the two
    green = fitted[changed]
    assert len({tuple(p) for p in green}) > 50
    both = png(c.get(f"/calibrations/{cal_id}/overlay.png?camera=both", headers=auth))
    assert np.any(both != fitted)  # start camera and legend entry added
    thumb = png(c.get(f"/calibrations/{cal_id}/overlay.png?width=240", headers=auth))
    assert thumb.shape == (135, 240, 3)
    assert_error(
        c.get(f"/calibrations/{cal_id}/overlay.png?camera=nope", headers=auth),
        422,
        "invalid_request",
    )


def test_edges_are_the_stored_line_evidence(calibrated: Calibrated) -> None:
    c, auth, cal_id = calibrated.client, calibrated.auth, calibrated.calibration["id"]
    edges = png(c.get(f"/calibrations/{cal_id}/edges.png", headers=auth))
    lit = edges.max(axis=2) > 0
    assert 0.002 < lit.mean() < 0.2
    # the evidence lies on the court lines: most points along them are near lit pixels (players
    # masked out may hide a few), and points between the lines are not
    near = cv2.dilate(lit.astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
    xs = np.linspace(0.3, 6.1, 30)
    on_lines = np.column_stack([xs, np.full(30, 9.75), np.zeros(30)])  # back wall's floor line
    between = np.column_stack([xs, np.zeros(30), np.full(30, -3.2)])  # plain front wall

    def share_near(points: np.ndarray) -> float:
        pixels = np.round(camera.project_visible(calibrated.truth, points)).astype(int)
        return float(np.mean([near[v, u] for u, v in pixels]))

    assert share_near(on_lines) > 0.8
    assert share_near(between) < 0.2


def test_topdown_marks_points_and_draws_heatmaps(calibrated: Calibrated) -> None:
    c, auth, cal_id = calibrated.client, calibrated.auth, calibrated.calibration["id"]
    plain = png(c.get(f"/calibrations/{cal_id}/topdown.png", headers=auth))
    t_pixel = camera.floor_to_pixel(calibrated.truth, np.array([[3.2, 5.465]]))[0]
    marked = png(
        c.get(
            f"/calibrations/{cal_id}/topdown.png",
            params={"points": f"{t_pixel[0]:.2f},{t_pixel[1]:.2f}"},
            headers=auth,
        )
    )
    assert plain.shape == marked.shape
    diff = np.argwhere(np.any(plain != marked, axis=2))
    centre = diff.mean(axis=0)  # (row, col) of the marker in the diagram: 64 px per metre
    assert centre[1] == pytest.approx(1.1 * 64 + 3.2 * 64, abs=12)
    assert centre[0] == pytest.approx(1.0 * 64 + 5.465 * 64, abs=12)
    rng = np.random.default_rng(0)
    feet = camera.floor_to_pixel(
        calibrated.truth, np.column_stack([rng.uniform(1, 5, 500), rng.uniform(4, 8, 500)])
    )
    heat = png(
        c.post(f"/calibrations/{cal_id}/topdown.png", json={"pixels": feet.tolist()}, headers=auth)
    )
    # 500 points make a density picture over the middle of the court, not 500 markers
    changed_by_heat = np.any(heat != plain, axis=2)
    assert changed_by_heat.sum() > 10 * len(diff)
    _, cols = np.nonzero(changed_by_heat)
    assert 1.1 * 64 + 1.0 * 64 < np.median(cols) < 1.1 * 64 + 5.4 * 64
    assert_error(
        c.get(f"/calibrations/{cal_id}/topdown.png?points=1,2,3", headers=auth),
        422,
        "invalid_points",
    )


def test_convergence_plots_the_ga_history(calibrated: Calibrated, tmp_path: Path) -> None:
    # the paper's GA runs only when a job names a bundle: its history is what the plot shows
    c, auth = calibrated.client, calibrated.auth
    clip = court_clip_bytes(tmp_path, calibrated.truth, SIZE, n_frames=20, seed=5)
    court_id = c.post("/courts", json={"name": "with the GA"}, headers=auth).json()["id"]
    response = c.post(
        f"/courts/{court_id}/calibrations",
        files=files(clip),
        data={"bundle": "n16-tdm-roulette-single-dist"},
        headers=auth,
    )
    assert response.status_code == 202, response.text
    assert run_one_job(calibrated.settings) == "succeeded"
    job = c.get(f"/jobs/{response.json()['job_id']}", headers=auth).json()
    cal_id = job["calibration_id"]
    image = png(c.get(f"/calibrations/{cal_id}/convergence.png", headers=auth))
    assert image.shape[1] == 960
    result = c.get(f"/calibrations/{cal_id}", headers=auth).json()
    assert result["timings_s"]["optimise"] > 0
    # the stored curve: best never decreases, mean never above best
    from app.db.models import Calibration
    from app.db.session import make_engine, make_sessionmaker

    engine = make_engine(calibrated.settings)
    with make_sessionmaker(engine)() as session:
        stored = session.get(Calibration, cal_id)
        assert stored is not None
        stages = {c["stage"]: c for c in stored.result["convergence"]}
        curve = stages["ga"]
    engine.dispose()
    best, mean = np.array(curve["best"]), np.array(curve["mean"])
    assert curve["x"][-1] == result["generations"]
    assert np.all(np.diff(best) >= 0) and np.all(mean <= best + 1e-9)


def test_lines_and_projection_through_one_calibration(calibrated: Calibrated) -> None:
    c, auth, cal_id = calibrated.client, calibrated.auth, calibrated.calibration["id"]
    lines = c.get(f"/calibrations/{cal_id}/lines", headers=auth).json()
    assert lines["image_size"] == list(SIZE) and lines["court_m"] == [6.4, 9.75]
    assert len(lines["fitted"]) >= 20 and lines["start"] is not None
    assert len(lines["floor"]["painted"]) == 9 and len(lines["floor"]["outline"]) == 9
    floor = np.array([[3.2, 5.465], [1.5, 8.0]])
    pixels = camera.floor_to_pixel(calibrated.truth, floor)
    body = c.post(
        f"/calibrations/{cal_id}/project", json={"pixels": pixels.tolist()}, headers=auth
    ).json()
    assert body["calibration_id"] == cal_id and body["inside_court"] == [True, True]
    assert np.abs(np.array(body["points"]) - floor).max() < 0.05
    back = c.post(
        f"/calibrations/{cal_id}/image-points", json={"points": floor.tolist()}, headers=auth
    ).json()
    assert np.abs(np.array(back["pixels"]) - pixels).max() < 3.0


def test_yaml_reads_back_with_filestorage(calibrated: Calibrated, tmp_path: Path) -> None:
    c, auth, cal = calibrated.client, calibrated.auth, calibrated.calibration
    response = c.get(f"/calibrations/{cal['id']}/camera.yaml", headers=auth)
    assert response.status_code == 200
    assert "attachment" in response.headers["content-disposition"]
    path = tmp_path / "camera.yaml"
    path.write_bytes(response.content)
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    try:
        assert np.allclose(storage.getNode("K").mat(), cal["opencv"]["K"], rtol=0, atol=1e-9)
        assert np.allclose(storage.getNode("dist").mat().ravel(), cal["opencv"]["dist"], atol=1e-12)
        assert np.allclose(storage.getNode("rvec").mat().ravel(), cal["opencv"]["rvec"], atol=1e-12)
        assert np.allclose(storage.getNode("tvec").mat().ravel(), cal["opencv"]["tvec"], atol=1e-12)
        size = [
            int(storage.getNode("image_width").real()),
            int(storage.getNode("image_height").real()),
        ]
        assert size == cal["opencv"]["image_size"]
    finally:
        storage.release()


def test_import_activate_and_history(calibrated: Calibrated) -> None:
    c, auth, court_id = calibrated.client, calibrated.auth, calibrated.court_id
    fitted = calibrated.calibration
    other = renderer.typical_target_camera(SIZE).copy()
    other[0:2] *= 1.1
    opencv = camera.to_opencv(other, SIZE)
    response = c.post(
        f"/courts/{court_id}/calibrations/import", json={"camera": opencv}, headers=auth
    )
    assert response.status_code == 201, response.text
    imported = response.json()
    assert imported["source"] == "import" and imported["job_id"] is None
    assert imported["fitness"] is None and imported["active"] is True
    assert np.allclose(imported["opencv"]["K"], opencv["K"])
    # the imported camera draws on a plain canvas: it has no picture
    png(c.get(f"/calibrations/{imported['id']}/overlay.png", headers=auth))
    png(c.get(f"/calibrations/{imported['id']}/convergence.png", headers=auth))
    history = c.get(f"/courts/{court_id}/calibrations", headers=auth).json()["calibrations"]
    assert [h["id"] for h in history] == [imported["id"], fitted["id"]]
    assert [h["active"] for h in history] == [True, False]
    # back to the fitted one: nothing disappears
    back = c.post(f"/courts/{court_id}/camera", json={"calibration_id": fitted["id"]}, headers=auth)
    assert back.status_code == 200 and back.json()["active"] is True
    assert c.get(f"/courts/{court_id}/camera", headers=auth).json()["id"] == fitted["id"]
    assert len(c.get(f"/courts/{court_id}/calibrations", headers=auth).json()["calibrations"]) == 2
    # bad input: words, not a 500
    no_size = {k: v for k, v in opencv.items() if k != "image_size"}
    assert_error(
        c.post(f"/courts/{court_id}/calibrations/import", json={"camera": no_size}, headers=auth),
        422,
        "invalid_camera",
    )
    assert_error(
        c.post(f"/courts/{court_id}/calibrations/import", json={"camera": {"K": 1}}, headers=auth),
        422,
        "invalid_camera",
    )
    assert_error(
        c.post(f"/courts/{court_id}/camera", json={"calibration_id": "nope"}, headers=auth),
        404,
        "calibration_not_found",
    )
    other_court = c.post("/courts", json={"name": "other"}, headers=auth).json()["id"]
    assert_error(
        c.post(
            f"/courts/{other_court}/camera", json={"calibration_id": fitted["id"]}, headers=auth
        ),
        422,
        "calibration_of_another_court",
    )


def test_jobs_list_me_config_and_static(calibrated: Calibrated) -> None:
    c, auth, court_id = calibrated.client, calibrated.auth, calibrated.court_id
    jobs = c.get(f"/courts/{court_id}/jobs", headers=auth).json()["jobs"]
    assert [j["status"] for j in jobs] == ["succeeded"]
    assert jobs[0]["calibration_id"] == calibrated.calibration["id"]
    me = c.get("/me", headers=auth).json()
    assert me["key_name"] == "coach" and me["tenant_name"] == "coach"
    assert c.get("/me").status_code == 401
    config = c.get("/ui/config").json()
    assert [s["name"] for s in config["specs"]] == ["wsf", "psa", "doubles"]
    assert config["max_upload_bytes"] == calibrated.settings.max_upload_bytes
    for name, kind in (("app.js", "javascript"), ("app.css", "css"), ("favicon.svg", "svg")):
        response = c.get(f"/static/{name}")
        assert response.status_code == 200 and kind in response.headers["content-type"], name
    assert c.get("/favicon.ico").status_code == 200
    for bad in ("..%2Fschemas.py", ".hidden.js", "nope.js", "index.py"):
        assert c.get(f"/static/{bad}").status_code == 404, bad


def test_other_tenants_see_no_pictures(calibrated: Calibrated) -> None:
    other = {"Authorization": f"Bearer {new_key(calibrated.settings, 'stranger')}"}
    cal_id = calibrated.calibration["id"]
    for path in (
        "overlay.png",
        "edges.png",
        "topdown.png",
        "convergence.png",
        "lines",
        "camera.yaml",
    ):
        assert_error(
            calibrated.client.get(f"/calibrations/{cal_id}/{path}", headers=other),
            404,
            "calibration_not_found",
        )


@pytest.mark.slow
def test_demo_clip_is_rendered_once_and_calibrates(tmp_path: Path, settings: Settings) -> None:
    auth = {"Authorization": f"Bearer {new_key(settings)}"}
    with api_client(create_app(settings)) as c:
        assert c.get("/demo/clip.mp4").status_code == 401
        first = c.get("/demo/clip.mp4", headers=auth)
        assert first.status_code == 200 and first.headers["content-type"] == "video/mp4"
        assert c.get("/demo/clip.mp4", headers=auth).content == first.content  # kept, not re-made
        court_id = c.post("/courts", json={"name": "demo"}, headers=auth).json()["id"]
        response = c.post(
            f"/courts/{court_id}/calibrations", files=files(first.content), headers=auth
        )
        assert response.status_code == 202, response.text
        assert run_one_job(settings) == "succeeded"
        pixel = camera.floor_to_pixel(
            renderer.typical_target_camera((1280, 720)), np.array([[3.2, 5.465]])
        )
        body = c.post(
            "/project", json={"court_id": court_id, "pixels": pixel.tolist()}, headers=auth
        ).json()
        assert np.abs(np.array(body["points"][0]) - [3.2, 5.465]).max() < 0.05

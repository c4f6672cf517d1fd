"""The /project hot path does no database work, and still sees new calibrations (on SQLite and
PostgreSQL)."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
import pytest
from sqlalchemy import event

from app.api.camera_cache import CameraCache
from app.calib import camera, synthetic
from app.db import queue, repo
from app.db.models import Calibration, new_id
from app.db.session import make_engine, make_sessionmaker
from app.main import create_app
from app.settings import Settings
from tests.service.conftest import api_client

pytestmark = pytest.mark.both_databases

SIZE = (1280, 720)


def calibrate_directly(engine, tenant_id: str, court_id: str, genome: np.ndarray) -> str:
    """Store a calibration of `genome` through the queue, as the worker does (known camera)."""
    with make_sessionmaker(engine).begin() as session:
        repo.new_job(
            session,
            job_id=new_id(),
            tenant_id=tenant_id,
            court_id=court_id,
            media_kind="images",
            media_files=[],
            params={},
            max_attempts=3,
        )
    job = queue.claim(engine, "w", 60)
    assert job is not None
    cal = Calibration(
        id=new_id(),
        tenant_id=tenant_id,
        court_id=court_id,
        job_id=job.id,
        spec="wsf",
        genome=[float(v) for v in genome],
        opencv=camera.to_opencv(genome, SIZE),
        fitness=1.0,
        quality={},
        result={},
        image_width=SIZE[0],
        image_height=SIZE[1],
    )
    queue.finish_success(engine, job, "w", cal, {})
    return cal.id


class StatementCounter:
    def __init__(self, engine) -> None:
        self.count = 0
        self.statements: list[str] = []
        event.listen(engine, "before_cursor_execute", self._on_execute)

    def _on_execute(self, conn, cursor, statement, *args, **kwargs) -> None:
        self.count += 1
        self.statements.append(statement)


def setup_court(settings: Settings) -> tuple[str, str, str]:
    engine = make_engine(settings)
    with make_sessionmaker(engine).begin() as session:
        key_row, key = repo.create_api_key(session, name="t")
        court = repo.create_court(session, key_row.tenant_id, "c", "wsf")
        tenant_id, court_id = key_row.tenant_id, court.id
    engine.dispose()
    return key, tenant_id, court_id


def test_cache_reads_no_database_and_refresh_picks_up_new_calibration(
    new_settings: Callable[..., Settings],
) -> None:
    settings = new_settings()
    _, tenant_id, court_id = setup_court(settings)
    engine = make_engine(settings)
    counter = StatementCounter(engine)
    cache = CameraCache(make_sessionmaker(engine), refresh_s=3600, max_courts=10)

    first = cache.get(tenant_id, court_id)  # cold: loads from the database
    assert first.calibration_id is None and first.genome is None
    loaded = counter.count
    assert loaded > 0
    for _ in range(50):
        assert cache.get(tenant_id, court_id) is not None
    assert counter.count == loaded  # warm: no database work at all

    genome = synthetic.typical_target_camera(SIZE)
    cal_id = calibrate_directly(engine, tenant_id, court_id, genome)
    assert cache.get(tenant_id, court_id).calibration_id is None  # not yet refreshed
    assert cache.refresh_once() == 1
    entry = cache.get(tenant_id, court_id)
    assert entry.calibration_id == cal_id
    assert entry.genome is not None
    np.testing.assert_array_equal(entry.genome, genome)
    assert entry.camera is not None
    np.testing.assert_array_equal(entry.camera.genome, genome)
    assert cache.refresh_once() == 0  # nothing changed since
    # the prepared camera is built once per calibration, not per refresh or request
    assert cache.get(tenant_id, court_id).camera is entry.camera
    engine.dispose()


def test_cache_is_bounded(new_settings: Callable[..., Settings]) -> None:
    settings = new_settings()
    engine = make_engine(settings)
    with make_sessionmaker(engine).begin() as session:
        key_row, _ = repo.create_api_key(session, name="t")
        court_ids = [
            repo.create_court(session, key_row.tenant_id, f"c{i}", "wsf").id for i in range(5)
        ]
    cache = CameraCache(make_sessionmaker(engine), refresh_s=3600, max_courts=3)
    for court_id in court_ids:
        cache.get(key_row.tenant_id, court_id)
    counter = StatementCounter(engine)
    cache.get(key_row.tenant_id, court_ids[-1])
    assert counter.count == 0
    cache.get(key_row.tenant_id, court_ids[0])  # evicted: loaded again
    assert counter.count > 0
    engine.dispose()


def test_project_hot_path_reads_only_the_key(new_settings: Callable[..., Settings]) -> None:
    settings = new_settings(camera_refresh_s=0.05)
    key, tenant_id, court_id = setup_court(settings)
    auth = {"Authorization": f"Bearer {key}"}
    genome = synthetic.typical_target_camera(SIZE)
    floor = np.array([[3.2, 5.44], [1.0, 8.0], [5.5, 2.0]])
    pixels = camera.floor_to_pixel(genome, floor)
    app = create_app(settings)
    state = app.state.squashcal
    with api_client(app) as client:
        cal_id = calibrate_directly(state.engine, tenant_id, court_id, genome)
        body = {"court_id": court_id, "pixels": pixels.tolist()}
        first = client.post("/project", json=body, headers=auth).json()
        assert first["calibration_id"] == cal_id
        np.testing.assert_allclose(first["points"], floor, atol=1e-6)
        # stop the background refresher's polling from counting: measure requests only
        state.cameras.refresh_s = 3600
        time.sleep(0.2)
        counter = StatementCounter(state.engine)
        key_checks = 0
        check_key = state.keys.tenant_for

        def counting_check(key: str) -> str | None:
            nonlocal key_checks
            key_checks += 1
            return check_key(key)

        state.keys.tenant_for = counting_check
        for _ in range(20):
            assert client.post("/project", json=body, headers=auth).status_code == 200
        # the camera comes from memory; the key is checked each time (revocation is immediate),
        # by one read on the driver's connection (repo.KeyLookup), nothing through SQLAlchemy
        assert counter.count == 0
        assert key_checks == 20


def test_a_calibrations_own_project_reads_it_once_and_keeps_it_after_a_new_one(
    new_settings: Callable[..., Settings],
) -> None:
    """/calibrations/{id}/project and /image-points: any calibration of the history, answered
    from memory after the first request (a calibration never changes), still the same camera
    after another one became active, and not another tenant's."""
    settings = new_settings(camera_refresh_s=3600)
    key, tenant_id, court_id = setup_court(settings)
    auth = {"Authorization": f"Bearer {key}"}
    first_genome = synthetic.typical_target_camera(SIZE)
    second_genome = first_genome.copy()
    second_genome[camera.GENE["t_x"]] += 0.5
    floor = np.array([[3.2, 5.44], [1.0, 8.0]])
    pixels = camera.floor_to_pixel(first_genome, floor)
    app = create_app(settings)
    state = app.state.squashcal
    with api_client(app) as client:
        first_id = calibrate_directly(state.engine, tenant_id, court_id, first_genome)
        calibrate_directly(state.engine, tenant_id, court_id, second_genome)
        counter = StatementCounter(state.engine)
        for _ in range(5):
            got = client.post(
                f"/calibrations/{first_id}/project", json={"pixels": pixels.tolist()}, headers=auth
            ).json()
            assert got["calibration_id"] == first_id
            np.testing.assert_allclose(got["points"], floor, atol=1e-6)
            back = client.post(
                f"/calibrations/{first_id}/image-points",
                json={"points": floor.tolist()},
                headers=auth,
            ).json()
            np.testing.assert_allclose(back["pixels"], pixels, atol=1e-3)
        # one load (the calibration's row) for ten requests
        assert 1 <= counter.count <= 2, counter.statements
        with make_sessionmaker(state.engine).begin() as session:
            _, other_key = repo.create_api_key(session, name="other")
        other = {"Authorization": f"Bearer {other_key}"}
        for path, body in (
            ("project", {"pixels": [[1.0, 2.0]]}),
            ("image-points", {"points": [[1.0, 2.0]]}),
        ):
            refused = client.post(f"/calibrations/{first_id}/{path}", json=body, headers=other)
            assert refused.status_code == 404, refused.text
            missing = client.post(f"/calibrations/nope/{path}", json=body, headers=auth)
            assert missing.status_code == 404, missing.text


def test_project_answers_null_where_the_ray_misses(new_settings: Callable[..., Settings]) -> None:
    settings = new_settings()
    key, tenant_id, court_id = setup_court(settings)
    auth = {"Authorization": f"Bearer {key}"}
    genome = synthetic.typical_target_camera(SIZE)
    app = create_app(settings)
    with api_client(app) as client:
        cal_id = calibrate_directly(app.state.squashcal.engine, tenant_id, court_id, genome)
        inside = camera.floor_to_pixel(genome, np.array([[3.2, 5.44]]))[0]
        outside = camera.floor_to_pixel(genome, np.array([[-1.0, 5.0]]))[0]
        sky = [640.0, -5000.0]  # far above the horizon: the ray never meets the floor
        body = {"court_id": court_id, "pixels": [inside.tolist(), outside.tolist(), sky]}
        got = client.post("/project", json=body, headers=auth).json()
        assert got["calibration_id"] == cal_id
        assert got["points"][2] is None
        np.testing.assert_allclose(got["points"][0], [3.2, 5.44], atol=1e-6)
        np.testing.assert_allclose(got["points"][1], [-1.0, 5.0], atol=1e-6)
        assert got["inside_court"] == [True, False, False]
        many = {"court_id": court_id, "pixels": [inside.tolist()] * 100_000}
        response = client.post("/project", json=many, headers=auth)
        assert response.status_code == 200
        assert len(response.json()["points"]) == 100_000


def test_project_body_edge_cases(new_settings: Callable[..., Settings]) -> None:
    """/project reads its body in one pass (app.api.json_body): the edges still answer as before."""
    settings = new_settings()
    key, tenant_id, court_id = setup_court(settings)
    auth = {"Authorization": f"Bearer {key}"}
    genome = synthetic.typical_target_camera(SIZE)
    app = create_app(settings)
    with api_client(app) as client:
        calibrate_directly(app.state.squashcal.engine, tenant_id, court_id, genome)
        empty = client.post("/project", json={"court_id": court_id, "pixels": []}, headers=auth)
        assert empty.status_code == 200, empty.text
        assert empty.json()["points"] == [] and empty.json()["inside_court"] == []
        body = b'{"court_id": "%s", "pixels": [[640, 400]]}' % court_id.encode()
        as_text = client.post(
            "/project", content=body, headers={**auth, "content-type": "text/plain"}
        )
        assert as_text.status_code == 422
        assert as_text.json()["error"]["code"] == "invalid_request"
        for content_type in ("application/json", "application/json; charset=utf-8"):
            ok = client.post(
                "/project", content=body, headers={**auth, "content-type": content_type}
            )
            assert ok.status_code == 200, ok.text
        # ints are floats; one field missing or extra is a 422 naming it
        missing = client.post("/project", json={"court_id": court_id}, headers=auth)
        assert missing.status_code == 422 and "pixels" in missing.json()["error"]["message"]
        extra = {"court_id": court_id, "pixels": [], "colour": "red"}
        response = client.post("/project", json=extra, headers=auth)
        assert response.status_code == 422 and "colour" in response.json()["error"]["message"]
        # unknown query parameters are refused on the hot path too (app.api.routing.ApiRoute)
        query = client.post(
            "/project?fast=1", json={"court_id": court_id, "pixels": []}, headers=auth
        )
        assert query.status_code == 422
        assert query.json()["error"]["code"] == "unknown_query_parameter"


def test_every_api_router_uses_the_checked_route_class() -> None:
    """The unknown-query check lives in the route class (not a dependency): a router made
    without it would silently accept misspelt parameters."""
    from app.api import ROUTER_MODULES
    from app.api.routing import ApiRoute

    routes = [route for module in ROUTER_MODULES for route in module.router.routes]
    assert len(routes) > 20
    assert all(isinstance(route, ApiRoute) for route in routes), [
        route for route in routes if not isinstance(route, ApiRoute)
    ]

"""Readiness waits for the numerical kernels (`create_app(warm_up=True)`, as `squashcal serve`),
and after them the projection endpoints compile nothing."""

from __future__ import annotations

import time

from app.calib import camera, synthetic, warmup
from app.main import create_app
from app.settings import Settings
from tests.service.conftest import api_client, new_key


def test_ready_only_after_the_kernels_are_loaded(settings: Settings) -> None:
    app = create_app(settings, warm_up=True)
    state = app.state.squashcal
    with api_client(app) as client:
        assert client.get("/healthz").status_code == 200  # alive while warming up
        deadline = time.monotonic() + 300  # a compile with an empty cache on a busy machine
        while not state.kernels_ready.is_set() and time.monotonic() < deadline:
            response = client.get("/readyz")
            if response.status_code == 503:
                assert response.json()["error"]["code"] == "warming_up"
            time.sleep(0.05)
        assert client.get("/readyz").status_code == 200
        state.kernels_ready.clear()
        response = client.get("/readyz")
        assert response.status_code == 503
        assert response.json()["error"]["code"] == "warming_up"


def test_projection_after_the_warm_up_compiles_nothing(settings: Settings) -> None:
    auth = {"Authorization": f"Bearer {new_key(settings)}"}
    size = (1920, 1080)
    opencv = camera.to_opencv(synthetic.typical_target_camera(size), size)
    warmup.warm_up(warmup.API_PARTS)
    with api_client(create_app(settings)) as client:
        court = client.post("/courts", json={"name": "c", "spec": "wsf"}, headers=auth).json()["id"]
        imported = client.post(
            f"/courts/{court}/calibrations/import", json={"camera": opencv}, headers=auth
        )
        assert imported.status_code in (200, 201), imported.text
        before = warmup.compiled_signatures()
        project = client.post(
            "/project", json={"court_id": court, "pixels": [[960, 700]]}, headers=auth
        )
        assert project.status_code == 200, project.text
        back = client.post(
            f"/courts/{court}/image-points", json={"points": [[3.2, 5.0]]}, headers=auth
        )
        assert back.status_code == 200, back.text
    after = warmup.compiled_signatures()
    assert {name: after[name] - before[name] for name in after if after[name] - before[name]} == {}

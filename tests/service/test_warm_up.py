"""Readiness waits for the numerical kernels (`create_app(warm_up=True)`, as `squashcal serve`)."""

from __future__ import annotations

import time

from app.main import create_app
from app.settings import Settings
from tests.service.conftest import api_client


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

"""A tenant's share of the queue: more uploads than max_queued_jobs_per_tenant waiting get 429."""

from __future__ import annotations

from collections.abc import Callable
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest
import sqlalchemy as sa

from app.db import queue
from app.db.migrate import upgrade_head
from app.db.models import UploadAttempt
from app.db.session import make_engine
from app.main import create_app
from app.settings import Settings
from tests.service.conftest import api_client, make_settings, new_key
from tests.service.helpers import files, png_bytes
from tests.service.test_api import assert_error, make_court
from tests.service.test_uploads import jobs_in_db, stored_job_dirs, upload


@pytest.mark.both_databases
def test_a_full_queue_is_429_with_retry_after_for_that_tenant_only(
    new_settings: Callable[..., Settings],
) -> None:
    settings = new_settings(max_queued_jobs_per_tenant=2, queue_full_retry_after_s=17)
    busy = {"Authorization": f"Bearer {new_key(settings, 'busy')}"}
    other = {"Authorization": f"Bearer {new_key(settings, 'other')}"}
    image = files(png_bytes(seed=1))
    with api_client(create_app(settings)) as client:
        court_id = make_court(client, busy)
        for _ in range(2):
            assert upload(client, busy, court_id, image).status_code == 202
        refused = upload(client, busy, court_id, image)
        assert_error(refused, 429, "too_many_queued_jobs")
        assert refused.headers["retry-after"] == "17"
        assert len(jobs_in_db(settings)) == 2 and len(stored_job_dirs(settings)) == 2

        # another tenant is not affected
        other_court = make_court(client, other)
        assert upload(client, other, other_court, image).status_code == 202

        # once a job is taken off the queue there is room again
        engine = make_engine(settings)
        try:
            assert queue.claim(engine, "w", settings.lease_s) is not None
        finally:
            engine.dispose()
        assert upload(client, busy, court_id, image).status_code == 202
        assert_error(upload(client, busy, court_id, image), 429, "too_many_queued_jobs")


def test_the_openapi_document_lists_429_for_uploads(tmp_path: Path) -> None:
    settings = make_settings(tmp_path / "data")
    upgrade_head(settings)
    with api_client(create_app(settings)) as client:
        spec = client.get("/openapi.json").json()
    assert "429" in spec["paths"]["/courts/{court_id}/calibrations"]["post"]["responses"]


def test_too_many_uploads_in_an_hour_are_429_with_retry_after_for_that_tenant_only(
    any_db_settings: Settings,
) -> None:
    """The upload rate counts every upload of the hour, whatever became of its job: a tenant
    whose jobs have all left the queue is still refused, until the oldest is an hour old."""
    settings = any_db_settings.model_copy(update={"max_uploads_per_hour_per_tenant": 2})
    busy = {"Authorization": f"Bearer {new_key(settings, 'busy')}"}
    other = {"Authorization": f"Bearer {new_key(settings, 'other')}"}
    image = files(png_bytes(seed=2))
    with api_client(create_app(settings)) as client:
        court_id = make_court(client, busy)
        for _ in range(2):
            assert upload(client, busy, court_id, image).status_code == 202
        engine = make_engine(settings)
        try:  # the queue is empty again: only the rate refuses
            while queue.claim(engine, "w", settings.lease_s) is not None:
                pass
        finally:
            engine.dispose()
        refused = upload(client, busy, court_id, image)
        assert_error(refused, 429, "too_many_uploads")
        assert 3590 <= int(refused.headers["retry-after"]) <= 3600
        assert len(jobs_in_db(settings)) == 2 and len(stored_job_dirs(settings)) == 2

        other_court = make_court(client, other)
        assert upload(client, other, other_court, image).status_code == 202

        # an hour after the first upload there is room for one more
        _age_first_upload_past_the_hour(settings)
        assert upload(client, busy, court_id, image).status_code == 202
        assert_error(upload(client, busy, court_id, image), 429, "too_many_uploads")


def _age_first_upload_past_the_hour(settings: Settings) -> None:
    engine = make_engine(settings)
    try:
        with engine.begin() as conn:
            first = conn.scalar(
                sa.select(UploadAttempt.id).order_by(UploadAttempt.received_at).limit(1)
            )
            an_hour_ago = datetime.now(UTC) - timedelta(hours=1, seconds=1)
            conn.execute(
                sa.update(UploadAttempt)
                .where(UploadAttempt.id == first)
                .values(received_at=an_hour_ago)
            )
    finally:
        engine.dispose()


def test_uploads_refused_for_their_content_count_toward_the_upload_rate(
    any_db_settings: Settings,
) -> None:
    """A client sending a file that is no picture in a loop is held to the rate too: every
    upload the API began to receive counts, a 429 does not (a client retrying it would
    otherwise never get out), and counted uploads older than the hour are forgotten."""
    settings = any_db_settings.model_copy(update={"max_uploads_per_hour_per_tenant": 2})
    busy = {"Authorization": f"Bearer {new_key(settings, 'busy')}"}
    not_a_picture = files(b"<html>not a picture</html>" * 20, name="court.png")
    with api_client(create_app(settings)) as client:
        court_id = make_court(client, busy)
        for _ in range(2):
            assert upload(client, busy, court_id, not_a_picture).status_code == 415
        for _ in range(3):
            assert_error(
                upload(client, busy, court_id, files(png_bytes(seed=3))), 429, "too_many_uploads"
            )
        assert jobs_in_db(settings) == [] and stored_job_dirs(settings) == []
        _age_first_upload_past_the_hour(settings)
        assert upload(client, busy, court_id, files(png_bytes(seed=3))).status_code == 202
        engine = make_engine(settings)
        try:
            with engine.connect() as conn:
                kept = conn.scalar(sa.select(sa.func.count()).select_from(UploadAttempt))
        finally:
            engine.dispose()
        assert kept == 2  # the aged one is gone: the second bad upload and the accepted one

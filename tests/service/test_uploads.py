"""Calibration uploads: accepted content is kept and queued; every bad input gets a clear 4xx."""

from __future__ import annotations

import json
import struct
import zlib
from collections.abc import Callable
from pathlib import Path

import httpx
import numpy as np
import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session

from app.db.models import Job
from app.db.session import make_engine, make_sessionmaker
from app.main import create_app
from app.settings import Settings
from tests.service.conftest import api_client, new_key
from tests.service.helpers import files, jpeg_bytes, png_bytes, video_bytes
from tests.service.test_api import assert_error, make_court

pytestmark = pytest.mark.both_databases


def jobs_in_db(settings: Settings) -> list[Job]:
    engine = make_engine(settings)
    try:
        with make_sessionmaker(engine)() as session:
            return list(session.scalars(select(Job)))
    finally:
        engine.dispose()


def stored_job_dirs(settings: Settings) -> list[Path]:
    root = settings.media_dir / "jobs"
    return sorted(root.iterdir()) if root.exists() else []


def upload(client: httpx.Client, auth: dict[str, str], court_id: str, parts, data=None):
    return client.post(f"/courts/{court_id}/calibrations", files=parts, data=data, headers=auth)


def assert_rejected_and_nothing_kept(
    response: httpx.Response, settings: Settings, status: int, code: str
) -> None:
    assert_error(response, status, code)
    assert jobs_in_db(settings) == []
    assert stored_job_dirs(settings) == []


def test_images_are_stored_and_queued(
    client: httpx.Client, auth: dict[str, str], settings: Settings
) -> None:
    court_id = make_court(client, auth)
    images = [png_bytes(seed=1), png_bytes(seed=2), png_bytes(seed=3)]
    response = upload(client, auth, court_id, files(*images, name="frame.mov"), data={"seed": "7"})
    assert response.status_code == 202, response.text
    job_id = response.json()["job_id"]
    assert response.json() == {"job_id": job_id, "status": "queued"}
    assert response.headers["location"] == f"/jobs/{job_id}"
    [job] = jobs_in_db(settings)
    assert (job.id, job.status, job.media_kind, job.attempts) == (job_id, "queued", "images", 0)
    assert job.params["seed"] == 7
    assert job.params["image_size"] == [64, 48]
    stored = [(stored_job_dirs(settings)[0] / name).read_bytes() for name in job.media_files]
    assert stored == images  # byte for byte, named by content type, not by the client's name
    assert all(name.endswith(".png") for name in job.media_files)
    got = client.get(f"/jobs/{job_id}", headers=auth).json()
    assert got["status"] == "queued"
    assert got["progress"] == 0
    assert got["n_files"] == 3
    assert got["error"] is None


def test_jpeg_and_video_are_accepted(
    client: httpx.Client, auth: dict[str, str], tmp_path: Path, settings: Settings
) -> None:
    court_id = make_court(client, auth)
    assert upload(client, auth, court_id, files(jpeg_bytes())).status_code == 202
    response = upload(client, auth, court_id, files(video_bytes(tmp_path), name="x.png"))
    assert response.status_code == 202, response.text
    kinds = sorted(j.media_kind for j in jobs_in_db(settings))
    assert kinds == ["images", "video"]


def test_empty_file(client: httpx.Client, auth: dict[str, str], settings: Settings) -> None:
    court_id = make_court(client, auth)
    response = upload(client, auth, court_id, files(png_bytes(), b""))
    assert_rejected_and_nothing_kept(response, settings, 422, "empty_file")


@pytest.mark.parametrize(
    "content",
    [b"hello, this is not an image at all" * 10, b"GIF89a" + bytes(100), b"%PDF-1.4\n" + bytes(80)],
)
def test_unsupported_type_by_content(
    client: httpx.Client, auth: dict[str, str], settings: Settings, content: bytes
) -> None:
    court_id = make_court(client, auth)
    parts = [("files", ("photo.png", content, "image/png"))]  # name and type lie
    assert_rejected_and_nothing_kept(
        upload(client, auth, court_id, parts), settings, 415, "unsupported_media_type"
    )


def test_truncated_images(client: httpx.Client, auth: dict[str, str], settings: Settings) -> None:
    court_id = make_court(client, auth)
    big_png = png_bytes(400, 300)
    big_jpeg = jpeg_bytes(400, 300)
    for data in (big_png[: len(big_png) // 2], big_jpeg[: len(big_jpeg) // 2]):
        response = upload(client, auth, court_id, files(data))
        assert_rejected_and_nothing_kept(response, settings, 422, "corrupt_image")


def test_corrupt_image_body(client: httpx.Client, auth: dict[str, str], settings: Settings) -> None:
    court_id = make_court(client, auth)
    data = bytearray(png_bytes(200, 100))
    data[60:-20] = bytes(len(data) - 80)  # header and end intact, compressed data destroyed
    response = upload(client, auth, court_id, files(bytes(data)))
    assert_rejected_and_nothing_kept(response, settings, 422, "corrupt_image")


def png_with_header_size(width: int, height: int) -> bytes:
    """A PNG whose IHDR claims width x height, with a tiny (inconsistent) body: a bomb's header."""
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    chunk = b"IHDR" + ihdr
    body = struct.pack(">I", len(ihdr)) + chunk + struct.pack(">I", zlib.crc32(chunk))
    idat = b"IDAT" + zlib.compress(bytes(1000))
    body += struct.pack(">I", len(idat) - 4) + idat + struct.pack(">I", zlib.crc32(idat))
    iend = b"IEND"
    body += struct.pack(">I", 0) + iend + struct.pack(">I", zlib.crc32(iend))
    return b"\x89PNG\r\n\x1a\n" + body


def test_decompression_bomb_rejected_from_header(
    client: httpx.Client, auth: dict[str, str], settings: Settings
) -> None:
    court_id = make_court(client, auth)
    bomb = png_with_header_size(100_000, 100_000)  # 10 gigapixels claimed in ~1 kB
    response = upload(client, auth, court_id, files(bomb))
    assert_rejected_and_nothing_kept(response, settings, 422, "image_too_large")


def test_image_pixel_limit_setting(new_settings: Callable[..., Settings]) -> None:
    settings = new_settings(max_image_pixels=100 * 100)
    auth = {"Authorization": f"Bearer {new_key(settings)}"}
    with api_client(create_app(settings)) as client:
        court_id = make_court(client, auth)
        assert upload(client, auth, court_id, files(png_bytes(100, 100))).status_code == 202
        response = upload(client, auth, court_id, files(png_bytes(101, 100)))
        assert_error(response, 422, "image_too_large")


def test_mixed_image_sizes(client: httpx.Client, auth: dict[str, str], settings: Settings) -> None:
    court_id = make_court(client, auth)
    response = upload(client, auth, court_id, files(png_bytes(64, 48), jpeg_bytes(64, 50)))
    assert_rejected_and_nothing_kept(response, settings, 422, "mixed_image_sizes")


def test_images_and_video_together(
    client: httpx.Client, auth: dict[str, str], settings: Settings, tmp_path: Path
) -> None:
    court_id = make_court(client, auth)
    clip = video_bytes(tmp_path)
    assert_rejected_and_nothing_kept(
        upload(client, auth, court_id, files(png_bytes(), clip)), settings, 422, "mixed_media"
    )
    assert_rejected_and_nothing_kept(
        upload(client, auth, court_id, files(clip, clip)), settings, 422, "too_many_videos"
    )


def test_truncated_video(
    client: httpx.Client, auth: dict[str, str], settings: Settings, tmp_path: Path
) -> None:
    court_id = make_court(client, auth)
    clip = video_bytes(tmp_path)
    response = upload(client, auth, court_id, files(clip[: len(clip) // 2]))
    assert_rejected_and_nothing_kept(response, settings, 422, "corrupt_video")


def test_video_without_decodable_frame(
    client: httpx.Client, auth: dict[str, str], settings: Settings, tmp_path: Path
) -> None:
    court_id = make_court(client, auth)
    clip = bytearray(video_bytes(tmp_path))
    start, end = clip.find(b"mdat") + 4, clip.find(b"moov") - 4
    assert 0 < start < end
    clip[start:end] = bytes(end - start)  # container intact, every frame's data zeroed
    response = upload(client, auth, court_id, files(bytes(clip)))
    assert_rejected_and_nothing_kept(response, settings, 422, "video_no_frames")


def test_video_limits(new_settings: Callable[..., Settings], tmp_path: Path) -> None:
    settings = new_settings(
        max_video_width_px=200, max_video_height_px=200, max_video_duration_s=1.0
    )
    auth = {"Authorization": f"Bearer {new_key(settings)}"}
    with api_client(create_app(settings)) as client:
        court_id = make_court(client, auth)
        ok = video_bytes(tmp_path, 160, 120, n_frames=20)
        assert upload(client, auth, court_id, files(ok)).status_code == 202
        wide = video_bytes(tmp_path, 320, 120, n_frames=5)
        assert_error(upload(client, auth, court_id, files(wide)), 422, "video_frame_too_large")
        long = video_bytes(tmp_path, 160, 120, n_frames=50)  # 2 s at 25 fps
        assert_error(upload(client, auth, court_id, files(long)), 422, "video_too_long")
    assert len(jobs_in_db(settings)) == 1


def test_upload_size_limit_is_413_and_keeps_nothing(new_settings: Callable[..., Settings]) -> None:
    settings = new_settings(max_upload_bytes=20_000)
    auth = {"Authorization": f"Bearer {new_key(settings)}"}
    with api_client(create_app(settings)) as client:
        court_id = make_court(client, auth)
        small = png_bytes(64, 64)
        assert len(small) < 20_000
        assert upload(client, auth, court_id, files(small)).status_code == 202
        big = png_bytes(200, 200)  # noise does not compress: ~120 kB
        assert len(big) > 20_000
        response = upload(client, auth, court_id, files(big))
        assert_error(response, 413, "upload_too_large")
        # several files that are each small but together too large
        response = upload(
            client, auth, court_id, files(*[png_bytes(64, 48, seed=s) for s in range(3)])
        )
        assert_error(response, 413, "upload_too_large")
    assert len(jobs_in_db(settings)) == 1
    assert len(stored_job_dirs(settings)) == 1
    leftovers = [p for d in stored_job_dirs(settings) for p in d.iterdir() if p.suffix == ".tmp"]
    assert leftovers == []


def test_too_many_files(new_settings: Callable[..., Settings]) -> None:
    settings = new_settings(max_files=2)
    auth = {"Authorization": f"Bearer {new_key(settings)}"}
    with api_client(create_app(settings)) as client:
        court_id = make_court(client, auth)
        response = upload(client, auth, court_id, files(png_bytes(), png_bytes(), png_bytes()))
        assert_error(response, 413, "too_many_files")
    assert stored_job_dirs(settings) == []


def test_not_multipart_and_no_files(
    client: httpx.Client, auth: dict[str, str], settings: Settings
) -> None:
    court_id = make_court(client, auth)
    response = client.post(f"/courts/{court_id}/calibrations", json={"files": []}, headers=auth)
    assert_rejected_and_nothing_kept(response, settings, 415, "unsupported_media_type")
    # a multipart body with form fields but no 'files' part
    response = client.post(
        f"/courts/{court_id}/calibrations",
        files=[("seed", (None, b"1"))],
        headers=auth,
    )
    assert_rejected_and_nothing_kept(response, settings, 422, "no_files")
    response = client.post(
        f"/courts/{court_id}/calibrations",
        content=b'--xyz\r\nContent-Disposition: form-data; name="files"; filename="a"\r\n\r\nabc',
        headers={**auth, "content-type": "multipart/form-data; boundary=xyz"},
    )
    assert_rejected_and_nothing_kept(response, settings, 422, "invalid_multipart")


def test_unknown_form_field(client: httpx.Client, auth: dict[str, str], settings: Settings) -> None:
    court_id = make_court(client, auth)
    response = upload(client, auth, court_id, files(png_bytes()), data={"colour": "red"})
    assert_rejected_and_nothing_kept(response, settings, 422, "unknown_field")


@pytest.mark.parametrize(
    ("data", "code"),
    [
        ({"start_camera": "{not json"}, "invalid_start_camera"),
        ({"start_camera": "[1, 2, 3]"}, "invalid_start_camera"),
        (
            {"start_camera": json.dumps({"K": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]})},
            "invalid_start_camera",
        ),
        ({"seed": "abc"}, "invalid_seed"),
        ({"seed": "-1"}, "invalid_seed"),
        ({"bundle": "no-such-bundle"}, "unknown_bundle"),
    ],
)
def test_bad_form_fields(
    client: httpx.Client, auth: dict[str, str], settings: Settings, data, code: str
) -> None:
    court_id = make_court(client, auth)
    response = upload(client, auth, court_id, files(png_bytes()), data=data)
    assert_rejected_and_nothing_kept(response, settings, 422, code)


def test_start_camera_forms_are_accepted_and_checked(
    client: httpx.Client, auth: dict[str, str], settings: Settings
) -> None:
    from app.calib import camera, synthetic

    court_id = make_court(client, auth)
    genome = synthetic.typical_target_camera((64, 48))
    opencv = camera.to_opencv(genome, (64, 48))
    for start in (json.dumps(list(genome)), json.dumps(opencv)):
        response = upload(client, auth, court_id, files(png_bytes()), data={"start_camera": start})
        assert response.status_code == 202, response.text
    for job in jobs_in_db(settings):
        np.testing.assert_allclose(job.params["start_genome"], genome, rtol=1e-9, atol=1e-9)
    wrong_size = json.dumps(camera.to_opencv(genome, (1920, 1080)))
    response = upload(client, auth, court_id, files(png_bytes()), data={"start_camera": wrong_size})
    assert_error(response, 422, "invalid_start_camera")


def test_upload_to_unknown_or_foreign_court(
    client: httpx.Client, auth: dict[str, str], other_auth: dict[str, str], settings: Settings
) -> None:
    court_id = make_court(client, auth)
    assert_error(upload(client, other_auth, court_id, files(png_bytes())), 404, "court_not_found")
    assert_error(upload(client, auth, "nope", files(png_bytes())), 404, "court_not_found")
    assert_error(client.post(f"/courts/{court_id}/calibrations", files=files(png_bytes())), 401)
    assert jobs_in_db(settings) == []


def test_random_bytes_never_cause_a_server_error(
    client: httpx.Client, auth: dict[str, str], settings: Settings
) -> None:
    court_id = make_court(client, auth)
    rng = np.random.default_rng(5)
    valid = png_bytes(80, 60)
    prefixes = [
        b"",
        b"\x89PNG\r\n\x1a\n",
        b"\xff\xd8\xff",
        b"\x1a\x45\xdf\xa3",
        b"RIFF\0\0\0\0AVI ",
    ]
    for i in range(25):
        prefix = prefixes[i % len(prefixes)]
        if i % 3 == 0:  # damage a valid image at a random place instead
            data = bytearray(valid)
            at = int(rng.integers(8, len(data)))
            data[at : at + 16] = rng.integers(0, 256, 16, dtype=np.uint8).tobytes()
            content = bytes(data)
        else:
            content = (
                prefix + rng.integers(0, 256, int(rng.integers(1, 3000)), dtype=np.uint8).tobytes()
            )
        response = upload(client, auth, court_id, files(content))
        assert response.status_code in (202, 413, 415, 422), (i, response.text)
        if response.status_code != 202:
            assert_error(response, response.status_code)


def test_size_limit_applies_while_streaming_without_content_length(
    new_settings: Callable[..., Settings],
) -> None:
    settings = new_settings(max_upload_bytes=50_000)
    auth = {"Authorization": f"Bearer {new_key(settings)}"}
    body = (
        b'--b\r\nContent-Disposition: form-data; name="files"; filename="a.png"\r\n\r\n'
        + png_bytes(400, 400)  # ~480 kB
        + b"\r\n--b--\r\n"
    )

    def chunks():
        for i in range(0, len(body), 8192):
            yield body[i : i + 8192]

    with api_client(create_app(settings)) as client:
        court_id = make_court(client, auth)
        response = client.post(
            f"/courts/{court_id}/calibrations",
            content=chunks(),
            headers={**auth, "content-type": "multipart/form-data; boundary=b"},
        )
        assert "content-length" not in {k.lower() for k in response.request.headers}
        assert_error(response, 413, "upload_too_large")
    assert stored_job_dirs(settings) == []
    assert jobs_in_db(settings) == []


@pytest.mark.parametrize("committed", [True, False])
def test_a_connection_lost_at_the_commit_keeps_an_accepted_upload(
    settings: Settings, auth: dict[str, str], committed: bool
) -> None:
    """The database connection drops as the job is committed. If the commit went through (only
    its acknowledgement was lost), the job exists: the upload is answered 202 with it and its
    media stay. If it did not, the answer is 503 (retry) and nothing is kept."""
    from sqlalchemy import event
    from sqlalchemy.exc import OperationalError

    app = create_app(settings)
    # the sessions the upload stores its job through
    sessions = app.state.squashcal.write_sessions
    pending = {"job": False}

    def connection_lost() -> OperationalError:
        return OperationalError("COMMIT", {}, Exception("server closed the connection"))

    def after_flush(session: Session, flush_context: object) -> None:
        # (the identity map holds objects weakly: by the commit the new job may have left it)
        if any(isinstance(obj, Job) for obj in session.new):
            session.info["new_job"] = True

    def before_commit(session: Session) -> None:
        if session.info.pop("new_job", False):
            if not committed:
                raise connection_lost()
            pending["job"] = True

    def after_commit(session: Session) -> None:
        if pending["job"]:
            pending["job"] = False
            raise connection_lost()

    event.listen(sessions, "after_flush", after_flush)
    event.listen(sessions, "before_commit", before_commit)
    event.listen(sessions, "after_commit", after_commit)
    with api_client(app) as client:
        court_id = make_court(client, auth)
        response = upload(client, auth, court_id, files(png_bytes(seed=4)))
    jobs = jobs_in_db(settings)
    if committed:
        assert response.status_code == 202, response.text
        [job] = jobs
        assert response.json() == {"job_id": job.id, "status": "queued"}
        assert [d.name for d in stored_job_dirs(settings)] == [job.id]
    else:
        assert_error(response, 503, "database_unavailable")
        assert jobs == []
        assert stored_job_dirs(settings) == []

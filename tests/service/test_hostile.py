"""Hostile input: a corpus of bad requests, each with the status and error code it must get.

Every case runs against a fresh API and database; none may get a 5xx, and none may leave a job or
media behind. Cases that need more than one request (revocation, paging) are separate tests below.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import httpx
import numpy as np
import pytest

from app.calib import camera, synthetic
from app.db import repo
from app.db.session import make_engine, make_sessionmaker
from app.main import create_app
from app.settings import Settings
from tests.service.conftest import api_client, new_key
from tests.service.helpers import files, jpeg_bytes, png_bytes, video_bytes
from tests.service.test_api import assert_error, make_court
from tests.service.test_camera_cache import SIZE, calibrate_directly, setup_court
from tests.service.test_uploads import jobs_in_db, png_with_header_size, stored_job_dirs

MAX_UPLOAD_BYTES = 2_000_000
MAX_JSON_BODY_BYTES = 4_000_000
MAX_IMAGES_BY_PIXELS = 3  # the corpus's pixel budget: three 64x48 images

pytestmark = pytest.mark.both_databases


@dataclass
class Target:
    """What a case can aim at: a court of its own tenant and one of another tenant."""

    client: httpx.Client
    auth: dict[str, str]
    court_id: str
    other_court_id: str
    tmp_path: Path
    settings: Settings

    def upload(self, parts: object, data: dict[str, str] | None = None) -> httpx.Response:
        return self.client.post(
            f"/courts/{self.court_id}/calibrations", files=parts, data=data, headers=self.auth
        )

    def raw_upload(self, body: bytes, content_type: str) -> httpx.Response:
        return self.client.post(
            f"/courts/{self.court_id}/calibrations",
            content=body,
            headers={**self.auth, "content-type": content_type},
        )

    def post_json_bytes(self, path: str, body: bytes) -> httpx.Response:
        return self.client.post(
            path, content=body, headers={**self.auth, "content-type": "application/json"}
        )


@pytest.fixture
def hostile_settings(new_settings: Callable[..., Settings]) -> Settings:
    return new_settings(
        max_upload_bytes=MAX_UPLOAD_BYTES,
        max_json_body_bytes=MAX_JSON_BODY_BYTES,
        max_upload_pixels=MAX_IMAGES_BY_PIXELS * 64 * 48,
    )


@pytest.fixture
def target(hostile_settings: Settings, tmp_path: Path) -> Iterator[Target]:
    auth = {"Authorization": f"Bearer {new_key(hostile_settings, 'tenant-a')}"}
    other = {"Authorization": f"Bearer {new_key(hostile_settings, 'tenant-b')}"}
    with api_client(create_app(hostile_settings)) as client:
        yield Target(
            client,
            auth,
            make_court(client, auth),
            make_court(client, other),
            tmp_path,
            hostile_settings,
        )


def _multipart_part(boundary: str, disposition: str, content: bytes) -> bytes:
    return (
        f"--{boundary}\r\nContent-Disposition: {disposition}\r\n\r\n".encode() + content + b"\r\n"
    )


def _multipart(boundary: str, disposition: str, content: bytes) -> bytes:
    return (
        f"--{boundary}\r\nContent-Disposition: {disposition}\r\n\r\n".encode()
        + content
        + f"\r\n--{boundary}--\r\n".encode()
    )


def _long_boundary(t: Target) -> httpx.Response:
    boundary = "a" * 5000
    body = _multipart(boundary, 'form-data; name="files"; filename="a.png"', png_bytes())
    return t.raw_upload(body, f"multipart/form-data; boundary={boundary}")


def _deep_start_camera(t: Target) -> httpx.Response:
    deep = "[" * 30_000 + "]" * 30_000
    return t.upload(files(png_bytes()), data={"start_camera": deep})


def _huge_json_declared(t: Target) -> httpx.Response:
    body = b'{"court_id": "x", "pixels": [' + b"[1.0, 2.0], " * 500_000 + b"[1, 2]]}"
    return t.post_json_bytes("/project", body)


def _huge_json_streamed(t: Target) -> httpx.Response:
    """No Content-Length: the limit must hold while the body is read."""

    def chunks() -> Iterator[bytes]:
        yield b'{"court_id": "x", "pixels": ['
        for _ in range(100):
            yield b"[1.0, 2.0], " * 5_000
        yield b"[1, 2]]}"

    return t.client.post(
        "/project", content=chunks(), headers={**t.auth, "content-type": "application/json"}
    )


def _huge_multipart_to_a_json_operation(t: Target) -> httpx.Response:
    """Only the upload streams multipart under its own limits; elsewhere the JSON limit holds."""
    body = _multipart("b", 'form-data; name="pixels"', b"1" * (MAX_JSON_BODY_BYTES + 1))
    return t.client.post(
        "/project",
        content=body,
        headers={**t.auth, "content-type": "multipart/form-data; boundary=b"},
    )


def _deep_json_camera_import(t: Target) -> httpx.Response:
    body = b'{"camera": ' + b"[" * 30_000 + b"]" * 30_000 + b"}"
    return t.post_json_bytes(f"/courts/{t.court_id}/camera", body)


def _one_file(data: bytes, name: str = "frame.png") -> list[tuple[str, tuple[str, bytes, str]]]:
    return [("files", (name, data, "image/png"))]


def _zero_bytes(t: Target) -> httpx.Response:
    return t.upload(_one_file(b""))


def _truncated_png(t: Target) -> httpx.Response:
    data = png_bytes(64, 48)
    return t.upload(_one_file(data[: len(data) // 2]))


def _truncated_jpeg(t: Target) -> httpx.Response:
    data = jpeg_bytes(64, 48)
    return t.upload(_one_file(data[: len(data) // 2], "frame.jpg"))


def _text_named_png(t: Target) -> httpx.Response:
    return t.upload(_one_file(b"just some text, honestly not a picture\n" * 20))


def _html_named_png(t: Target) -> httpx.Response:
    html = b"<!DOCTYPE html><html><body><script>alert(1)</script></body></html>" * 4
    return t.upload(_one_file(html))


def _png_declaring_100000_square(t: Target) -> httpx.Response:
    return t.upload(_one_file(png_with_header_size(100_000, 100_000)))


def _png_declaring_7000_square(t: Target) -> httpx.Response:
    """The 142 KB PNG of zeros that used to pass: 49 Mpx is over the per-image limit."""
    return t.upload(_one_file(png_with_header_size(7000, 7000)))


def zeros_png(width: int, height: int) -> bytes:
    """A real, valid PNG of black RGB pixels, compressed row by row (never whole in memory)."""
    compressor = zlib.compressobj(9)
    row = bytes(1 + 3 * width)  # filter byte + pixels
    idat = b"".join(compressor.compress(row) for _ in range(height)) + compressor.flush()

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (
            struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
        )

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", idat) + chunk(b"IEND", b"")


ZEROS_7000 = zeros_png(7000, 7000)  # ~142 KB that decode to 147 MB


def _real_png_of_7000_square_zeros(t: Target) -> httpx.Response:
    return t.upload(_one_file(ZEROS_7000))


def _png_1x1(t: Target) -> httpx.Response:
    return t.upload(_one_file(png_bytes(1, 1)))


def _jpeg_16x16(t: Target) -> httpx.Response:
    return t.upload(_one_file(jpeg_bytes(16, 16), "frame.jpg"))


def _video_32x32(t: Target) -> httpx.Response:
    return t.upload(_one_file(video_bytes(t.tmp_path, 32, 32, n_frames=5), "clip.mp4"))


def _video_without_frames(t: Target) -> httpx.Response:
    clip = bytearray(video_bytes(t.tmp_path))
    start, end = clip.find(b"mdat") + 4, clip.find(b"moov") - 4
    clip[start:end] = bytes(end - start)  # container intact, every frame's data zeroed
    return t.upload(_one_file(bytes(clip), "clip.mp4"))


def _video_absurd_size(t: Target) -> httpx.Response:
    """A clip of 4160 x 64 frames: wider than any camera the limit allows."""
    return t.upload(_one_file(video_bytes(t.tmp_path, 4160, 64, n_frames=3), "clip.mp4"))


def _upload_over_size_limit_streamed(t: Target) -> httpx.Response:
    """No Content-Length: the limit must hold while the body streams in."""
    boundary = "hostile"
    head = (
        f'--{boundary}\r\nContent-Disposition: form-data; name="files"; filename="big.png"\r\n\r\n'
    ).encode()
    image = png_bytes(64, 48)

    def chunks() -> Iterator[bytes]:
        yield head + image
        for _ in range(MAX_UPLOAD_BYTES // 65_536 + 2):
            yield bytes(65_536)
        yield f"\r\n--{boundary}--\r\n".encode()

    return t.client.post(
        f"/courts/{t.court_id}/calibrations",
        content=chunks(),
        headers={**t.auth, "content-type": f"multipart/form-data; boundary={boundary}"},
    )


def _too_many_pixels(t: Target) -> httpx.Response:
    return t.upload(files(*[png_bytes(64, 48, seed=s) for s in range(MAX_IMAGES_BY_PIXELS + 1)]))


def _wrong_field_name(t: Target) -> httpx.Response:
    return t.upload([("file", ("frame.png", png_bytes(), "image/png"))])


def _files_part_without_filename(t: Target) -> httpx.Response:
    body = _multipart("b", 'form-data; name="files"', png_bytes())
    return t.raw_upload(body, "multipart/form-data; boundary=b")


def _unknown_form_field(t: Target) -> httpx.Response:
    return t.upload(files(png_bytes()), data={"court": "mine"})


def _duplicate_form_field(t: Target) -> httpx.Response:
    body = (
        _multipart_part("b", 'form-data; name="files"; filename="a.png"', png_bytes())
        + _multipart_part("b", 'form-data; name="seed"', b"1")
        + _multipart_part("b", 'form-data; name="seed"', b"2")
        + b"--b--\r\n"
    )
    return t.raw_upload(body, "multipart/form-data; boundary=b")


def _huge_form_field(t: Target) -> httpx.Response:
    return t.upload(files(png_bytes()), data={"start_camera": "[" + "1, " * 40_000 + "1]"})


def _json_instead_of_multipart(t: Target) -> httpx.Response:
    return t.client.post(
        f"/courts/{t.court_id}/calibrations", json={"files": ["a.png"]}, headers=t.auth
    )


def _multipart_without_boundary(t: Target) -> httpx.Response:
    return t.raw_upload(b"--x\r\n\r\n", "multipart/form-data")


def _seed_out_of_range(t: Target) -> httpx.Response:
    return t.upload(files(png_bytes()), data={"seed": str(2**64)})


def _project_raw(t: Target, pixels: bytes) -> httpx.Response:
    body = b'{"court_id": "' + t.court_id.encode() + b'", "pixels": ' + pixels + b"}"
    return t.post_json_bytes("/project", body)


def _project_nan(t: Target) -> httpx.Response:
    return _project_raw(t, b"[[NaN, 1.0]]")


def _project_infinity(t: Target) -> httpx.Response:
    return _project_raw(t, b"[[1.0, Infinity]]")


def _project_huge_number(t: Target) -> httpx.Response:
    return _project_raw(t, b"[[1e999, 1.0]]")  # parses to inf


def _project_strings(t: Target) -> httpx.Response:
    return _project_raw(t, b'[["12", "x"]]')


def _project_triples(t: Target) -> httpx.Response:
    return _project_raw(t, b"[[1, 2, 3]]")


def _project_100001_points(t: Target) -> httpx.Response:
    return _project_raw(t, b"[" + b"[1,2]," * 100_000 + b"[1,2]]")


def _project_not_json(t: Target) -> httpx.Response:
    return t.post_json_bytes("/project", b'{"court_id": "x", "pixels": [[1, 2]')


def _project_unknown_court(t: Target) -> httpx.Response:
    return t.client.post("/project", json={"court_id": "nope", "pixels": []}, headers=t.auth)


def _project_other_tenants_court(t: Target) -> httpx.Response:
    body = {"court_id": t.other_court_id, "pixels": [[1, 2]]}
    return t.client.post("/project", json=body, headers=t.auth)


def _image_points_nan(t: Target) -> httpx.Response:
    return t.post_json_bytes(f"/courts/{t.court_id}/image-points", b'{"points": [[NaN, 0]]}')


def _upload_to_other_tenants_court(t: Target) -> httpx.Response:
    return t.client.post(
        f"/courts/{t.other_court_id}/calibrations", files=files(png_bytes()), headers=t.auth
    )


def _unknown_job(t: Target) -> httpx.Response:
    return t.client.get("/jobs/0123456789abcdef0123456789abcdef", headers=t.auth)


def _unknown_calibration(t: Target) -> httpx.Response:
    return t.client.get("/calibrations/../../etc/passwd", headers=t.auth)


def _other_tenants_court(t: Target) -> httpx.Response:
    return t.client.get(f"/courts/{t.other_court_id}", headers=t.auth)


def _court_with_empty_name(t: Target) -> httpx.Response:
    return t.client.post("/courts", json={"name": ""}, headers=t.auth)


def _court_with_unknown_spec(t: Target) -> httpx.Response:
    return t.client.post("/courts", json={"name": "x", "spec": "tennis"}, headers=t.auth)


# PostgreSQL refuses a NUL character in any text it is sent, where SQLite stores it: both must
# answer these alike, and neither with a 500
def _court_name_with_nul(t: Target) -> httpx.Response:
    return t.client.post("/courts", json={"name": "a\u0000b"}, headers=t.auth)


def _nul_in_a_court_id(t: Target) -> httpx.Response:
    return t.client.get(f"/courts/{t.court_id}%00", headers=t.auth)


def _nul_in_a_job_id(t: Target) -> httpx.Response:
    return t.client.get("/jobs/a%00b", headers=t.auth)


def _project_nul_in_the_court_id(t: Target) -> httpx.Response:
    return t.client.post(
        "/project", json={"court_id": f"{t.court_id}\u0000", "pixels": [[1, 2]]}, headers=t.auth
    )


def _missing_key(t: Target) -> httpx.Response:
    return t.client.get("/courts")


def _malformed_key(t: Target) -> httpx.Response:
    return t.client.get("/courts", headers={"Authorization": "Bearer"})


def _basic_auth(t: Target) -> httpx.Response:
    return t.client.get("/courts", headers={"Authorization": "Basic dXNlcjpwYXNz"})


def _huge_key(t: Target) -> httpx.Response:
    return t.client.get("/courts", headers={"Authorization": "Bearer " + "k" * 20_000})


def _unknown_key(t: Target) -> httpx.Response:
    return t.client.get("/courts", headers={"Authorization": "Bearer sqc_" + "A" * 43})


def _revoked_key(t: Target) -> httpx.Response:
    engine = make_engine(t.settings)
    try:
        with make_sessionmaker(engine).begin() as session:
            row, key = repo.create_api_key(session, name="revoked")
        headers = {"Authorization": f"Bearer {key}"}
        assert t.client.get("/courts", headers=headers).status_code == 200
        with make_sessionmaker(engine).begin() as session:
            repo.revoke_api_key(session, row.id)
    finally:
        engine.dispose()
    return t.client.get("/courts", headers=headers)  # at once: no cache period


@dataclass(frozen=True)
class Case:
    name: str
    send: Callable[[Target], httpx.Response]
    status: int
    code: str


CORPUS = [
    # files
    Case("zero-byte file", _zero_bytes, 422, "empty_file"),
    Case("truncated PNG", _truncated_png, 422, "corrupt_image"),
    Case("truncated JPEG", _truncated_jpeg, 422, "corrupt_image"),
    Case("text named .png", _text_named_png, 415, "unsupported_media_type"),
    Case("HTML named .png", _html_named_png, 415, "unsupported_media_type"),
    Case("PNG declaring 100000x100000", _png_declaring_100000_square, 422, "image_too_large"),
    Case("PNG declaring 7000x7000", _png_declaring_7000_square, 422, "image_too_large"),
    Case(
        "real 142 KB PNG of 7000x7000 zeros", _real_png_of_7000_square_zeros, 422, "image_too_large"
    ),
    Case("valid 1x1 PNG", _png_1x1, 422, "image_too_small"),
    Case("valid 16x16 JPEG", _jpeg_16x16, 422, "image_too_small"),
    Case("32x32 video", _video_32x32, 422, "video_frame_too_small"),
    Case("video without decodable frames", _video_without_frames, 422, "video_no_frames"),
    Case("video of 4160x64 frames", _video_absurd_size, 422, "video_frame_too_large"),
    Case("upload over the size limit", _upload_over_size_limit_streamed, 413, "upload_too_large"),
    Case("images over the pixel budget", _too_many_pixels, 413, "too_many_pixels"),
    # multipart framing and form fields
    Case("multipart boundary of 5000 characters", _long_boundary, 422, "invalid_multipart"),
    Case("multipart without boundary", _multipart_without_boundary, 415, "unsupported_media_type"),
    Case("JSON instead of multipart", _json_instead_of_multipart, 415, "unsupported_media_type"),
    Case("field 'file' instead of 'files'", _wrong_field_name, 422, "unknown_field"),
    Case("'files' part that is not a file", _files_part_without_filename, 422, "invalid_multipart"),
    Case("unknown form field", _unknown_form_field, 422, "unknown_field"),
    Case("form field twice", _duplicate_form_field, 422, "duplicate_field"),
    Case("form field over 64 KB", _huge_form_field, 413, "field_too_large"),
    Case("seed beyond 2^63", _seed_out_of_range, 422, "invalid_seed"),
    Case("start_camera nested 30 000 deep", _deep_start_camera, 422, "invalid_start_camera"),
    # JSON bodies
    Case("JSON body over the limit (declared)", _huge_json_declared, 413, "body_too_large"),
    Case("JSON body over the limit (streamed)", _huge_json_streamed, 413, "body_too_large"),
    Case(
        "multipart over the limit to /project",
        _huge_multipart_to_a_json_operation,
        413,
        "body_too_large",
    ),
    Case("JSON nested 30 000 deep", _deep_json_camera_import, 400, "invalid_json"),
    Case("malformed JSON", _project_not_json, 422, "invalid_request"),
    Case("/project NaN", _project_nan, 422, "invalid_request"),
    Case("/project Infinity", _project_infinity, 422, "invalid_request"),
    Case("/project 1e999", _project_huge_number, 422, "invalid_request"),
    Case("/project strings", _project_strings, 422, "invalid_request"),
    Case("/project triples", _project_triples, 422, "invalid_request"),
    Case("/project 100 001 points", _project_100001_points, 422, "invalid_request"),
    Case("image-points NaN", _image_points_nan, 422, "invalid_request"),
    Case("court with empty name", _court_with_empty_name, 422, "invalid_request"),
    Case("court with unknown spec", _court_with_unknown_spec, 422, "invalid_request"),
    Case("court name with a NUL character", _court_name_with_nul, 422, "invalid_request"),
    # ids
    Case("/project unknown court", _project_unknown_court, 404, "court_not_found"),
    Case("/project other tenant's court", _project_other_tenants_court, 404, "court_not_found"),
    Case("upload to other tenant's court", _upload_to_other_tenants_court, 404, "court_not_found"),
    Case("other tenant's court", _other_tenants_court, 404, "court_not_found"),
    Case("unknown job", _unknown_job, 404, "job_not_found"),
    Case("path tricks in a calibration id", _unknown_calibration, 404, "not_found"),
    Case("NUL in a court id", _nul_in_a_court_id, 404, "court_not_found"),
    Case("NUL in a job id", _nul_in_a_job_id, 404, "job_not_found"),
    Case("/project NUL in the court id", _project_nul_in_the_court_id, 404, "court_not_found"),
    # keys
    Case("missing key", _missing_key, 401, "unauthorized"),
    Case("empty bearer key", _malformed_key, 401, "unauthorized"),
    Case("basic auth instead of a key", _basic_auth, 401, "unauthorized"),
    Case("20 000-character key", _huge_key, 401, "unauthorized"),
    Case("unknown key", _unknown_key, 401, "unauthorized"),
    Case("revoked key, at once", _revoked_key, 401, "unauthorized"),
]


def test_the_corpus_is_large_and_names_are_unique() -> None:
    assert len(CORPUS) >= 30
    assert len({c.name for c in CORPUS}) == len(CORPUS)


@pytest.mark.parametrize("case", CORPUS, ids=[c.name for c in CORPUS])
def test_bad_request_is_refused(case: Case, target: Target, hostile_settings: Settings) -> None:
    response = case.send(target)
    assert_error(response, case.status, case.code)
    assert jobs_in_db(hostile_settings) == []
    assert stored_job_dirs(hostile_settings) == []


@pytest.mark.parametrize(
    "name", ["../../../evil.png", "/etc/passwd", "..\\..\\win.png", "..", "a/../../b.png"]
)
def test_client_file_names_never_reach_the_filesystem(
    name: str, target: Target, hostile_settings: Settings
) -> None:
    response = target.upload([("files", (name, png_bytes(), "image/png"))])
    assert response.status_code == 202, response.text
    [job] = jobs_in_db(hostile_settings)
    assert job.media_files == ["000.png"]  # named by index and sniffed type only
    [folder] = stored_job_dirs(hostile_settings)
    assert sorted(p.name for p in folder.iterdir()) == ["000.png"]
    stray = [p for p in hostile_settings.data_dir.rglob("*") if p.suffix == ".png"]
    assert stray == [folder / "000.png"]


def test_image_points_beyond_the_lens_fold_are_not_in_the_image(settings: Settings) -> None:
    """A strong barrel lens folds back past ~47 degrees off-axis: floor points out there have
    ghost pixels inside the picture; the API must not report them as seen."""
    key, tenant_id, court_id = setup_court(settings)
    genome = synthetic.typical_target_camera(SIZE).copy()
    genome[camera.GENE["k1"]], genome[camera.GENE["k2"]], genome[camera.GENE["k3"]] = -0.3, 0, 0
    xs, ys = np.meshgrid(np.linspace(-30, 36, 60), np.linspace(-30, 40, 60))
    floor = np.column_stack([xs.ravel(), ys.ravel()])
    ghost_pixels = camera.floor_to_pixel(genome, floor)
    field = camera.in_lens_field(genome, np.column_stack([floor, np.zeros(len(floor))]))
    ghosts = camera.pixels_in_image(ghost_pixels, SIZE) & ~field
    assert ghosts.sum() > 50  # the raw projection does put points past the fold in the picture
    app = create_app(settings)
    with api_client(app) as client:
        calibrate_directly(app.state.squashcal.engine, tenant_id, court_id, genome)
        response = client.post(
            f"/courts/{court_id}/image-points",
            json={"points": floor.tolist()},
            headers={"Authorization": f"Bearer {key}"},
        )
    assert response.status_code == 200, response.text
    body = response.json()
    in_image = np.array(body["in_image"])
    assert not in_image[ghosts].any()
    assert all(body["pixels"][i] is None for i in np.flatnonzero(~field))
    # points well inside the field still map to their pixels
    seen = camera.pixels_in_image(ghost_pixels, SIZE) & field
    assert in_image[seen].all()


def test_revoked_key_is_refused_at_once_by_every_api_process(hostile_settings: Settings) -> None:
    engine = make_engine(hostile_settings)
    with make_sessionmaker(engine).begin() as session:
        row, key = repo.create_api_key(session, name="soon revoked")
    headers = {"Authorization": f"Bearer {key}"}
    # two API processes' worth of state, both having just accepted the key
    with (
        api_client(create_app(hostile_settings)) as first,
        api_client(create_app(hostile_settings)) as second,
    ):
        assert first.get("/courts", headers=headers).status_code == 200
        assert second.get("/courts", headers=headers).status_code == 200
        with make_sessionmaker(engine).begin() as session:
            assert repo.revoke_api_key(session, row.id)
        for client in (first, second):
            assert_error(client.get("/courts", headers=headers), 401, "unauthorized")
    engine.dispose()


def test_courts_are_listed_a_page_at_a_time(target: Target) -> None:
    t = target
    for i in range(4):
        make_court(t.client, t.auth, f"extra {i}")
    seen: list[str] = []
    offset: int | None = 0
    while offset is not None:
        page = t.client.get(f"/courts?limit=2&offset={offset}", headers=t.auth).json()
        assert len(page["courts"]) <= 2
        seen += [c["id"] for c in page["courts"]]
        offset = page["next_offset"]
    assert len(seen) == len(set(seen)) == 5  # the fixture's court and 4 more, none twice
    assert t.other_court_id not in seen
    for bad in ("limit=0", "limit=501", "offset=-1", "offset=99999999999999999999", "limit=x"):
        assert_error(t.client.get(f"/courts?{bad}", headers=t.auth), 422, "invalid_request")


def test_a_courts_calibrations_are_listed_a_page_at_a_time(target: Target) -> None:
    t = target
    genome = synthetic.typical_target_camera(SIZE)
    imported = []
    for i in range(5):
        moved = genome.copy()
        moved[camera.GENE["t_x"]] += 0.1 * i
        response = t.client.post(
            f"/courts/{t.court_id}/calibrations/import",
            json={"camera": camera.to_opencv(moved, SIZE)},
            headers=t.auth,
        )
        assert response.status_code == 201, response.text
        imported.append(response.json()["id"])
    seen: list[str] = []
    offset: int | None = 0
    while offset is not None:
        page = t.client.get(
            f"/courts/{t.court_id}/calibrations?limit=2&offset={offset}", headers=t.auth
        ).json()
        assert len(page["calibrations"]) <= 2
        seen += [c["id"] for c in page["calibrations"]]
        offset = page["next_offset"]
    assert seen == imported[::-1]  # newest first, each once
    whole = t.client.get(f"/courts/{t.court_id}/calibrations", headers=t.auth).json()
    assert [c["id"] for c in whole["calibrations"]] == seen and whole["next_offset"] is None
    assert [c["active"] for c in whole["calibrations"]] == [True] + [False] * 4
    path = f"/courts/{t.court_id}/calibrations"
    for bad in ("limit=0", "limit=501", "offset=-1", "offset=99999999999999999999", "limit=x"):
        assert_error(t.client.get(f"{path}?{bad}", headers=t.auth), 422, "invalid_request")
    other = t.client.get(f"/courts/{t.other_court_id}/calibrations?limit=2", headers=t.auth)
    assert_error(other, 404)


def test_key_lookup_on_both_databases(any_db_settings: Settings) -> None:
    engine = make_engine(any_db_settings)
    try:
        with make_sessionmaker(engine).begin() as session:
            row, key = repo.create_api_key(session, name="k")
        lookup = repo.KeyLookup(engine)
        assert lookup.tenant_for(key) == row.tenant_id
        assert lookup.tenant_for(key + "x") is None
        assert lookup.tenant_for("' OR 1=1 --") is None
        with make_sessionmaker(engine).begin() as session:
            repo.revoke_api_key(session, row.id)
        assert lookup.tenant_for(key) is None
    finally:
        engine.dispose()

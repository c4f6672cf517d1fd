"""Uploads to a real API process (`squashcal serve`: uvicorn on a port) over real connections,
where the in-process client cannot look: the process killed in the middle of an upload, and an
upload far over the size limit streamed to it (issue 8)."""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest

from app.settings import Settings
from tests.service.conftest import make_settings, new_key
from tests.service.helpers import files, png_bytes
from tests.service.test_api import assert_error, make_court
from tests.service.test_e2e import LiveService
from tests.service.test_supervisor import wait_until
from tests.service.test_uploads import jobs_in_db, stored_job_dirs

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")

LIMIT = 2_000_000  # SQUASHCAL_MAX_UPLOAD_BYTES of these API processes
ORPHAN_GRACE_S = 0.2  # SQUASHCAL_ORPHAN_MEDIA_GRACE_S: a job folder this quiet may be swept


@dataclass
class LiveApi:
    service: LiveService
    settings: Settings  # the API's data dir and database, to look behind its back
    client: httpx.Client
    auth: dict[str, str]
    court_id: str

    @property
    def process(self) -> subprocess.Popen[bytes]:
        return self.service.processes[-1]  # the API process started last


@pytest.fixture
def live_api(tmp_path: Path, database_url: str | None) -> Iterator[LiveApi]:
    """An API process (no kernel warm-up: these tests calibrate nothing) with a key and a court."""
    overrides = {
        "database_url": database_url,
        "max_upload_bytes": LIMIT,
        "orphan_media_grace_s": ORPHAN_GRACE_S,
    }
    service = LiveService(tmp_path / "data", warm_up=0, **overrides)
    try:
        service.start_api()
        settings = make_settings(tmp_path / "data", **overrides)
        auth = {"Authorization": f"Bearer {new_key(settings)}"}
        with httpx.Client(base_url=service.url, timeout=30) as client:
            yield LiveApi(service, settings, client, auth, make_court(client, auth))
    finally:
        service.stop()


def upload_request(live: LiveApi, content: bytes) -> httpx.Request:
    return live.client.build_request(
        "POST", f"/courts/{live.court_id}/calibrations", files=files(content), headers=live.auth
    )


def send_half(live: LiveApi, request: httpx.Request) -> socket.socket:
    """A connection that has sent the request's head and the first half of its body (declared
    whole by its Content-Length); the rest never comes."""
    body = request.read()
    head = f"{request.method} {request.url.raw_path.decode()} HTTP/1.1\r\n" + "".join(
        f"{name}: {value}\r\n" for name, value in request.headers.items()
    )
    sock = socket.create_connection(("127.0.0.1", live.service.port), timeout=10)
    sock.sendall(f"{head}\r\n".encode() + body[: len(body) // 2])
    return sock


def partial_files(settings: Settings) -> list[Path]:
    """Files of uploads being received (a part is renamed from .tmp once it has ended)."""
    return [p for d in stored_job_dirs(settings) for p in d.iterdir() if p.suffix == ".tmp"]


@pytest.mark.both_databases
def test_an_api_killed_during_an_upload_leaves_no_job_and_its_media_are_swept(
    live_api: LiveApi,
) -> None:
    live = live_api
    request = upload_request(live, png_bytes(600, 600))  # ~1 MB: noise does not compress
    with send_half(live, request):
        wait_until(
            lambda: any(p.stat().st_size > 0 for p in partial_files(live.settings)),
            10,
            "the API to store part of the upload",
        )
        live.process.send_signal(signal.SIGKILL)
        assert live.process.wait(10) == -signal.SIGKILL
    # the kill left half a file in a job folder, and the job was never committed
    assert partial_files(live.settings), "no half upload on disk: the kill came too late"
    assert jobs_in_db(live.settings) == []
    # The sweep leaves folders written to within the grace period (an upload in progress on
    # another host): wait that long, so that the sweep at the API's start may take this one.
    # Its periodic sweep is an hour away: only the one at start can pass the checks below.
    time.sleep(ORPHAN_GRACE_S)

    live.service.start_api()
    jobs = live.client.get(f"/courts/{live.court_id}/jobs", headers=live.auth).json()["jobs"]
    assert jobs == []
    wait_until(lambda: stored_job_dirs(live.settings) == [], 10, "the sweep at start")
    assert [p for p in live.settings.media_dir.rglob("*") if p.is_file()] == []
    # the service is whole again: the same upload, sent in full, is accepted
    response = live.client.send(upload_request(live, png_bytes(600, 600)))
    assert response.status_code == 202, response.text
    [job] = jobs_in_db(live.settings)
    assert [d.name for d in stored_job_dirs(live.settings)] == [job.id]


BODY_BYTES = 20 * LIMIT
CHUNK = bytes(64 * 1024)


class StreamedFile:
    """A multipart body (no Content-Length: chunked) of one PNG file padded to `BODY_BYTES`, made
    as the client sends it; `sent` counts the bytes handed to the client so far."""

    def __init__(self) -> None:
        self.sent = 0

    def __iter__(self) -> Iterator[bytes]:
        head = b'--b\r\nContent-Disposition: form-data; name="files"; filename="big.png"\r\n\r\n'
        yield head + png_bytes()  # a real PNG's signature: the type check passes
        while self.sent < BODY_BYTES:
            self.sent += len(CHUNK)
            yield CHUNK
        yield b"\r\n--b--\r\n"


def memory_bytes(pid: int, field: str) -> int:
    """VmRSS (resident now) or VmHWM (its peak since the last reset) of a process."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(f"{field}:"):
            return int(line.split()[1]) * 1024  # "VmRSS:    290512 kB"
    raise AssertionError(f"no {field} in /proc/{pid}/status")


def test_an_upload_far_over_the_limit_is_refused_while_it_streams_in_flat_memory(
    live_api: LiveApi,
) -> None:
    live = live_api
    # a refused upload first: what the first one allocates for good (lazily imported code, the
    # parser's tables) is not what is measured
    assert_error(live.client.send(upload_request(live, b"not an image" * 10)), 415)
    pid = live.process.pid
    before = memory_bytes(pid, "VmRSS")
    Path(f"/proc/{pid}/clear_refs").write_text("5")  # VmHWM := VmRSS (proc(5))
    body = StreamedFile()
    response = live.client.post(
        f"/courts/{live.court_id}/calibrations",
        content=body,
        headers={**live.auth, "content-type": "multipart/form-data; boundary=b"},
    )
    peak_growth = memory_bytes(pid, "VmHWM") - before

    # no declared length to refuse the upload from: the limit was applied to what arrived
    assert "content-length" not in response.request.headers
    assert_error(response, 413, "upload_too_large")
    # The server read up to the limit and no more, and closed the connection: the client got out
    # only what the two sockets' buffers hold beyond that (a few MB on loopback). A server that
    # read on to the end, even to discard it, would have taken the whole body.
    assert response.headers["connection"] == "close"
    assert body.sent < BODY_BYTES / 2, f"the client sent {body.sent} of {BODY_BYTES} bytes"
    # Its memory did not follow the body: the peak grows by about 1 MB here (the connection's and
    # the parser's buffers), the same for any body; a server that held the body would need 40 MB.
    assert peak_growth < BODY_BYTES / 10, f"the API's peak memory grew by {peak_growth} bytes"
    assert jobs_in_db(live.settings) == []
    assert stored_job_dirs(live.settings) == []

"""The page as a coach uses it, in Chromium, against the real API and worker.

Full flow on a synthetic clip: key, court, drag and drop, live progress to success, overlay
toggles, click on the picture -> metres (vs the synthetic truth), click on the diagram -> pixel,
JSON and YAML downloads (YAML read back with cv2.FileStorage), the demo button, switching the
active calibration; at 1280 and 390 px wide. Screenshots of each step: test-artifacts/browser/.
"""

from __future__ import annotations

import base64
import json
import time
from datetime import timedelta
from pathlib import Path

import cv2
import httpx
import numpy as np
import pytest
from playwright.sync_api import Route

from app.calib import camera, cases
from app.db import queue, repo
from app.db.models import new_id, utcnow
from app.db.session import make_engine, make_sessionmaker
from app.settings import Settings
from tests import renderer
from tests.browser.conftest import Session, open_page
from tests.service.test_e2e import LiveService

pytestmark = [pytest.mark.e2e, pytest.mark.browser]

SIZE = (1280, 720)
T_M = (3.2, 5.465)
FLOOR_POINTS_M = [T_M, (1.5, 7.5), (4.9, 3.0)]
DIAGRAM_POINT_M = (1.6, 8.0)


def clip_file(tmp_path: Path, genome: np.ndarray, seed: int) -> Path:
    frames = renderer.render_clip_frames(genome, SIZE, 30, seed, n_players=2)
    path = tmp_path / f"rally-{seed}.mp4"
    renderer.write_video(frames, path)
    return path


def blank_clip(tmp_path: Path) -> Path:
    """A clip of a static view with no court in it (a room the benchmark uses as a negative),
    long enough (1.6 s) to give a background: the calibration itself must refuse it."""
    room = cases.make_negative("room", 1000).image
    frame = cv2.resize(room, SIZE, interpolation=cv2.INTER_AREA)
    path = tmp_path / "no-court.mp4"
    renderer.write_video([frame] * 40, path)
    return path


def drop_files(s: Session, *files: tuple[str, bytes, str]) -> None:
    """Drag and drop files onto the drop zone, as a person dragging from their desktop."""
    payload = [
        {"name": name, "b64": base64.b64encode(data).decode(), "type": kind}
        for name, data, kind in files
    ]
    transfer = s.page.evaluate_handle(
        """(files) => {
            const dt = new DataTransfer();
            for (const f of files) {
                const bytes = Uint8Array.from(atob(f.b64), (c) => c.charCodeAt(0));
                dt.items.add(new File([bytes], f.name, { type: f.type }));
            }
            return dt;
        }""",
        payload,
    )
    for event in ("dragenter", "dragover", "drop"):
        s.page.dispatch_event("#drop", event, {"dataTransfer": transfer})


def no_sideways_scroll(s: Session) -> None:
    overflow = s.page.evaluate(
        "document.documentElement.scrollWidth - document.documentElement.clientWidth"
    )
    assert overflow <= 0, f"the page scrolls sideways by {overflow} px"


def every_control_labelled(s: Session) -> None:
    unlabelled = s.page.evaluate(
        """() => [...document.querySelectorAll('input, select, textarea, button, canvas[tabindex]')]
            .filter((e) => !(e.labels && e.labels.length) && !e.getAttribute('aria-label')
                          && !(e.textContent || '').trim())
            .map((e) => e.id || e.outerHTML.slice(0, 80))"""
    )
    assert unlabelled == []


def answer_busy_once(s: Session, url_pattern: str) -> list[str]:
    """Answer the first POST to `url_pattern` with the 503 a busy database gives (the
    service did nothing); the URLs so answered are collected in the returned list."""
    answered: list[str] = []

    def busy_once(route: Route) -> None:
        if route.request.method == "POST" and not answered:
            answered.append(route.request.url)
            route.fulfill(
                status=503,
                headers={"Retry-After": "1", "Content-Type": "application/json"},
                body='{"error": {"code": "database_unavailable", "message": "retry shortly"}}',
            )
        else:
            route.continue_()

    s.page.route(url_pattern, busy_once)
    return answered


def wait_for_page(s: Session, condition_js: str, timeout_s: float) -> None:
    """Wait for `condition_js`, failing at once with the page's words if an upload error
    shows instead (a refused upload never brings the awaited card)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if s.page.evaluate(condition_js):
            return
        error = s.page.inner_text("#upload-error").strip()
        if error:
            raise AssertionError(f"the upload was refused: {error}; {page_state(s)}")
        s.page.wait_for_timeout(200)
    raise AssertionError(
        f"timed out after {timeout_s} s waiting for {condition_js}: {page_state(s)}"
    )


def wait_job_done(s: Session, stages_seen: set[str], progress_seen: list[float]) -> None:
    """Watch the newest job card until it succeeds or fails, noting stages and progress."""
    page = s.page
    card = page.locator("#jobs li.job").first
    deadline = time.monotonic() + 240
    # the card shows once the upload is stored and the list refreshed: on a busy 2-core machine
    # (a worker calibrating beside the API and the browser) that has taken over Playwright's
    # default 30 s, so it gets the job's own deadline
    wait_for_page(s, "() => document.querySelector('#jobs li.job') !== null", 240)
    shot_running = False
    while time.monotonic() < deadline:
        # one snapshot of the card per poll: the page re-renders it as the job moves on, so
        # separate reads (a stage counted, then read) can race with a re-render
        state = card.evaluate(
            """c => ({
                classes: c.className,
                now: c.querySelector('.stages li.now')?.innerText ?? null,
                progress: c.dataset.progress ?? null,
                line: c.querySelector('p.line')?.innerText ?? '',
            })"""
        )
        if state["now"] is not None:
            stages_seen.add(state["now"])
        if state["progress"] is not None:
            progress_seen.append(float(state["progress"]))
        if not shot_running and "Fitting the camera" in state["line"]:
            s.shot("04-job-running")
            shot_running = True
        if "succeeded" in state["classes"] or "failed" in state["classes"]:
            return
        page.wait_for_timeout(150)
    raise AssertionError("the job card never finished")


def wait_settled(s: Session) -> None:
    """Wait until the page has no request or image decode in flight (it says aria-busy)."""
    s.page.wait_for_function("() => document.body.getAttribute('aria-busy') === 'false'")


def page_state(s: Session) -> dict[str, object]:
    """What a failing wait reports: the history as shown, the page's error boxes, and the
    browser's problems so far."""
    shown = s.page.evaluate(
        """() => ({
            history: [...document.querySelectorAll('#history li')].map((li) => li.innerText),
            errors: [...document.querySelectorAll('.error')].map((e) => e.innerText).filter(Boolean),
        })"""
    )
    return {**shown, "problems": s.problems.all()}


def canvas_pixels(s: Session) -> np.ndarray:
    data_url = s.page.evaluate("document.getElementById('viewer').toDataURL('image/png')")
    raw = base64.b64decode(data_url.split(",", 1)[1])
    return cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_COLOR)


def click_image_pixel(s: Session, u: float, v: float, zoom_steps: int = 6) -> None:
    """Zoom in on image pixel (u, v) with the mouse wheel, as a person aiming at a spot would,
    then click it. Starts from the 'Fit' view."""
    page = s.page
    s.page.click("#zoom-fit")
    canvas = page.locator("#viewer")
    canvas.scroll_into_view_if_needed()
    box = canvas.bounding_box()
    scale = box["width"] / SIZE[0]
    page.mouse.move(box["x"] + (u + 0.5) * scale, box["y"] + (v + 0.5) * scale)
    for _ in range(zoom_steps):
        page.mouse.wheel(0, -120)
        page.wait_for_timeout(30)
    # where the page now shows the pixel, in CSS pixels of the canvas
    x, y = page.evaluate("([u, v]) => viewer.toCanvas(u, v).map((c) => c / viewer.ratio())", [u, v])
    box = canvas.bounding_box()
    assert 0 <= x <= box["width"] and 0 <= y <= box["height"]
    page.mouse.click(box["x"] + x, box["y"] + y)


def click_diagram_metres(s: Session, x: float, y: float) -> None:
    s.page.locator("#diagram").scroll_into_view_if_needed()
    point = s.page.evaluate(
        """([x, y]) => {
            const svg = document.getElementById('diagram');
            const p = svg.createSVGPoint(); p.x = x; p.y = y;
            const q = p.matrixTransform(svg.getScreenCTM());
            return [q.x, q.y];
        }""",
        [x, y],
    )
    s.page.mouse.click(point[0], point[1])


def open_new_court(s: Session) -> None:
    """Open the "New court" box (the page opens it by itself when there is no court yet)."""
    # the court list is loaded (it holds "No court yet" when empty): the page is done opening
    s.page.wait_for_selector("#app:not([hidden]) #courts option", state="attached")
    if not s.page.eval_on_selector("#new-court-box", "d => d.open"):
        s.page.click("#new-court-box summary")


def clear_readout(s: Session) -> None:
    s.page.evaluate("document.getElementById('readout').textContent = ''")


def readout(s: Session, *keys: str) -> tuple[float, ...]:
    data = s.page.locator("#readout")
    return tuple(float(data.get_attribute(f"data-{k}")) for k in keys)


@pytest.mark.slow
@pytest.mark.parametrize("width", [1280, 390])
def test_coach_flow(browser, live, tmp_path: Path, width: int) -> None:
    truth = renderer.typical_target_camera(SIZE)
    clip = clip_file(tmp_path, truth, seed=31)
    key = live.cli("keys", "create", "--name", "coach").strip().splitlines()[-1]
    auth = {"Authorization": f"Bearer {key}"}
    s = open_page(browser, live.url, width, f"flow-{width}")
    page = s.page

    # sign in: Enter submits; the page says who is signed in
    page.goto(live.url + "/")
    s.shot("01-sign-in")
    page.fill("#key", key)
    page.press("#key", "Enter")
    page.wait_for_selector("#who-text:has-text('Signed in as coach')")

    # create a court (spec chosen from the list)
    open_new_court(s)
    page.fill("#court-name", f"Club court {width}")
    page.select_option("#court-spec", "wsf")
    page.click("#create-court")
    page.wait_for_selector(f"#courts option:has-text('Club court {width}')", state="attached")
    court_id = page.eval_on_selector("#courts", "s => s.value")
    assert court_id
    s.shot("02-court")

    # a file that is not footage: refused in the browser, in plain words, nothing sent
    drop_files(s, ("notes.txt", b"hello", "text/plain"))
    assert "not a photo or clip" in page.inner_text("#upload-error")
    s.shot("03-rejected-file")

    # drag and drop the clip; watch the job through its stages to success
    drop_files(s, (clip.name, clip.read_bytes(), "video/mp4"))
    stages: set[str] = set()
    progress: list[float] = []
    wait_job_done(s, stages, progress)
    card = page.locator("#jobs li.job").first
    assert "succeeded" in (card.get_attribute("class") or ""), card.inner_text()
    assert progress == sorted(progress) and progress[-1] == 1.0
    assert "Fitting the camera" in stages
    page.wait_for_selector("#result:not([hidden]) #verdict strong")
    page.wait_for_function("() => document.getElementById('diagram').childElementCount > 5")
    page.wait_for_function("() => viewer.background !== null && viewer.edges !== null")
    s.shot("05-result")
    first_cal = httpx.get(f"{live.url}/courts/{court_id}/camera", headers=auth).json()

    # overlay toggles change the picture
    fitted = canvas_pixels(s)
    page.uncheck("#show-fitted")
    bare = canvas_pixels(s)
    page.check("#show-edges")
    edges = canvas_pixels(s)
    assert np.abs(fitted.astype(int) - bare.astype(int)).sum() > 0
    assert np.abs(edges.astype(int) - bare.astype(int)).sum() > 0
    s.shot("06-line-evidence")
    page.uncheck("#show-edges")
    page.check("#show-start")
    page.check("#show-fitted")
    s.shot("07-fitted-and-start")

    # click the picture: floor metres within 5 cm of the synthetic truth
    for x, y in FLOOR_POINTS_M:
        ((u, v),) = camera.floor_to_pixel(truth, np.array([[x, y]]))
        clear_readout(s)
        click_image_pixel(s, u, v)
        page.wait_for_function(
            "() => document.getElementById('readout').textContent.startsWith('Floor position')"
        )
        got = np.array(readout(s, "x", "y"))
        assert np.linalg.norm(got - [x, y]) < 0.05, (x, y, got)
    s.shot("08-clicked-picture")

    # click the diagram: the spot is marked in the picture
    clear_readout(s)
    click_diagram_metres(s, *DIAGRAM_POINT_M)
    page.wait_for_function(
        "() => document.getElementById('readout').textContent.startsWith('Floor (')"
    )
    ((u_true, v_true),) = camera.floor_to_pixel(truth, np.array([DIAGRAM_POINT_M]))
    u, v = readout(s, "u", "v")
    assert abs(u - u_true) < 4 and abs(v - v_true) < 4
    s.shot("09-clicked-diagram")

    # the camera: JSON and OpenCV YAML downloads
    with page.expect_download() as info:
        page.click("#download-json")
    downloaded = json.loads(Path(info.value.path()).read_text())
    assert downloaded == first_cal["opencv"]
    with page.expect_download() as info:
        page.click("#download-yaml")
    yaml_path = tmp_path / "camera.yaml"
    info.value.save_as(str(yaml_path))
    storage = cv2.FileStorage(str(yaml_path), cv2.FILE_STORAGE_READ)
    try:
        assert np.allclose(storage.getNode("K").mat(), downloaded["K"], atol=1e-9)
        assert np.allclose(storage.getNode("dist").mat().ravel(), downloaded["dist"], atol=1e-12)
        assert np.allclose(storage.getNode("rvec").mat().ravel(), downloaded["rvec"], atol=1e-12)
        assert np.allclose(storage.getNode("tvec").mat().ravel(), downloaded["tvec"], atol=1e-12)
        assert int(storage.getNode("image_width").real()) == SIZE[0]
    finally:
        storage.release()
    page.click("#convergence-box summary")
    page.wait_for_function("() => document.getElementById('convergence').dataset.id")
    s.shot("10-camera-panel")

    # try it without footage: a second calibration through the same flow. The service's first
    # answer to the upload is a 503 (its database busy for a moment, as SQLite is when a worker
    # writes under load): the page sends the files again after the Retry-After.
    busy_uploads = answer_busy_once(s, f"**/courts/{court_id}/calibrations")
    page.click("#demo")
    # the card shows once the demo clip is rendered (the first request renders it, compiling
    # the renderer on a fresh checkout) and uploaded: on a busy 2-core machine that has taken
    # over Playwright's default 30 s (a fresh-clone CI run), so it gets the job's own deadline
    wait_for_page(s, "() => document.querySelectorAll('#jobs li.job').length === 2", 240)
    page.unroute(f"**/courts/{court_id}/calibrations")
    assert len(busy_uploads) == 1
    wait_job_done(s, set(), [])
    page.wait_for_function("() => document.querySelectorAll('#history li[data-id]').length === 2")
    second = httpx.get(f"{live.url}/courts/{court_id}/camera", headers=auth).json()
    assert second["id"] != first_cal["id"]
    s.shot("11-demo-done")

    # switch the active calibration back to the first one; both stay in the history. The
    # service's first answer is a 503 (its database busy for a moment, as SQLite is when a
    # worker writes under load): the page waits the Retry-After and sends the request again.
    wait_settled(s)
    busy_answers = answer_busy_once(s, f"**/courts/{court_id}/camera")
    older = page.locator(f"#history li[data-id='{first_cal['id']}']")
    older.get_by_role("button", name="Make active").click()
    try:
        page.wait_for_selector(f"#history li[data-id='{first_cal['id']}'] .badge.active")
    except Exception as error:  # say what the page showed, not only that it timed out
        raise AssertionError(
            f"the first calibration never became active: {page_state(s)}"
        ) from error
    page.unroute(f"**/courts/{court_id}/camera")
    assert len(busy_answers) == 1
    assert (
        httpx.get(f"{live.url}/courts/{court_id}/camera", headers=auth).json()["id"]
        == (first_cal["id"])
    )
    assert page.locator("#history li[data-id]").count() == 2
    s.shot("12-history-switched")

    # the chosen court survives a reload (once the page has settled: a reload cancels what is
    # in flight, which the page's problem log would record as a failed request)
    wait_settled(s)
    page.reload()
    page.wait_for_selector("#result:not([hidden]) #verdict strong")
    assert page.eval_on_selector("#courts", "s => s.value") == court_id

    no_sideways_scroll(s)
    every_control_labelled(s)
    if width == 1280:  # the middle width: same page, laid out for a tablet
        page.set_viewport_size({"width": 768, "height": 1000})
        page.wait_for_timeout(300)
        no_sideways_scroll(s)
        s.shot("13-tablet-768")
    # the browser reports a 503 like any error response: the injected ones, and any the busy
    # service gave on its own, were sent again (the steps above would not have passed otherwise)
    s.problems.console = [p for p in s.problems.console if "503" not in p]
    s.problems.requests = [p for p in s.problems.requests if not p.startswith("HTTP 503:")]
    assert s.problems.all() == []


@pytest.mark.slow
def test_failed_job_says_why_and_what_to_refilm(browser, live, tmp_path: Path) -> None:
    key = live.cli("keys", "create", "--name", "coach").strip().splitlines()[-1]
    s = open_page(browser, live.url, 1280, "failed-job")
    page = s.page
    page.goto(live.url + "/")
    page.fill("#key", key)
    page.click("#key-form button")
    open_new_court(s)
    page.fill("#court-name", "Empty hall")
    page.click("#create-court")
    page.wait_for_selector("#courts option:has-text('Empty hall')", state="attached")
    page.set_input_files("#files", str(blank_clip(tmp_path)))
    wait_job_done(s, set(), [])
    card = page.locator("#jobs li.job").first
    assert "failed" in (card.get_attribute("class") or "")
    text = card.inner_text()
    assert "Failed" in text and "Re-film" in text and "court_not_found" in text
    assert not card.locator("progress").is_visible()  # no bar left half-full
    assert card.locator(".stages li.failed").count() == 1
    s.shot("01-failed-job")
    assert s.problems.all() == []


def test_a_job_whose_worker_stopped_responding_says_so(browser, tmp_path: Path) -> None:
    """A running job whose worker was killed (its lease ran out: `stale` in GET /jobs/{id}) says
    that the worker stopped responding and that the job will be retried. The API runs without a
    worker here, so nothing takes the job up again while the page shows it."""
    data_dir = tmp_path / "data"
    service = LiveService(data_dir)
    try:
        service.start_api()
        key = service.cli("keys", "create", "--name", "coach").strip().splitlines()[-1]
        auth = {"Authorization": f"Bearer {key}"}
        court = httpx.post(f"{service.url}/courts", json={"name": "Club court"}, headers=auth)
        assert court.status_code == 201, court.text
        engine = make_engine(Settings(data_dir=data_dir))
        try:
            with make_sessionmaker(engine).begin() as session:
                tenant_id = repo.tenant_for_key(session, key)
                assert tenant_id is not None
                repo.new_job(
                    session,
                    job_id=new_id(),
                    tenant_id=tenant_id,
                    court_id=court.json()["id"],
                    media_kind="video",
                    media_files=["000.mp4"],
                    params={},
                    max_attempts=3,
                )
            # its worker was SIGKILLed just after renewing a 10 s lease, 15 s ago
            assert queue.claim(engine, "killed", lease_s=10, now=utcnow() - timedelta(seconds=15))
        finally:
            engine.dispose()

        s = open_page(browser, service.url, 1280, "stale-job")
        page = s.page
        page.goto(service.url + "/")
        page.fill("#key", key)
        page.click("#key-form button")
        page.wait_for_selector("#jobs li.job.stale")
        text = page.locator("#jobs li.job").first.inner_text()
        assert "The worker stopped responding: the job will be retried" in text, text
        assert "attempt 1 of 3" in text, text
        s.shot("01-stale-job")
        assert s.problems.all() == []
    finally:
        service.stop()

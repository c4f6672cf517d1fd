"""Playwright (Python) driving Debian's Chromium against a real API and worker.

The browser is /usr/bin/chromium (Debian's `chromium` package; `.ci/run` installs it when
missing): no browser download. Every page collects console errors, failed requests and HTTP
errors; a test fails if any happened that it did not expect. Screenshots go to
test-artifacts/browser/ (gitignored). The page is served with a strict Content-Security-Policy
added here, so inline scripts or styles would show up as console errors.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from playwright.sync_api import Browser, Page, Route

from tests.service.test_e2e import LiveService

REPO_ROOT = Path(__file__).resolve().parents[2]
ARTIFACTS = REPO_ROOT / "test-artifacts" / "browser"
CHROMIUM = os.environ.get("SQUASHCAL_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--disable-quic",
]
STRICT_CSP = (
    "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self'; "
    "connect-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'"
)


@pytest.fixture(scope="session")
def browser() -> Iterator[Browser]:
    from playwright.sync_api import sync_playwright

    if not Path(CHROMIUM).is_file():
        pytest.fail(f"{CHROMIUM} is missing: apt-get install chromium chromium-driver")
    with sync_playwright() as playwright:
        chromium = playwright.chromium.launch(
            executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS
        )
        yield chromium
        chromium.close()


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveService]:
    """API (uvicorn) and one worker, real processes, own data directory and port."""
    service = LiveService(tmp_path_factory.mktemp("browser") / "data")
    try:
        service.start_api()
        service.start_worker()
        yield service
    finally:
        service.stop()


@dataclass
class Problems:
    """What went wrong in the browser: console errors, failed requests, HTTP errors."""

    console: list[str] = field(default_factory=list)
    requests: list[str] = field(default_factory=list)

    def all(self) -> list[str]:
        return self.console + self.requests


@dataclass
class Session:
    page: Page
    problems: Problems
    shots: Path
    base_url: str

    def shot(self, name: str) -> Path:
        path = self.shots / f"{name}.png"
        self.page.screenshot(path=str(path), full_page=True)
        return path


def open_page(browser: Browser, base_url: str, width: int, name: str) -> Session:
    context = browser.new_context(
        viewport={"width": width, "height": 900 if width > 500 else 844},
        accept_downloads=True,
        device_scale_factor=1,
    )
    page = context.new_page()
    problems = Problems()
    page.on(
        "console",
        lambda m: (
            problems.console.append(f"console {m.type}: {m.text}") if m.type == "error" else None
        ),
    )
    page.on("pageerror", lambda e: problems.console.append(f"page error: {e}"))
    page.on("requestfailed", lambda r: problems.requests.append(f"failed: {r.method} {r.url}"))
    page.on(
        "response",
        lambda r: (
            problems.requests.append(f"HTTP {r.status}: {r.request.method} {r.url}")
            if r.status >= 400
            else None
        ),
    )

    def with_csp(route: Route) -> None:
        response = route.fetch()
        headers = {**response.headers, "content-security-policy": STRICT_CSP}
        route.fulfill(response=response, headers=headers)

    page.route(re.compile(re.escape(base_url) + r"/(\?.*)?$"), with_csp)
    shots = ARTIFACTS / name
    shots.mkdir(parents=True, exist_ok=True)
    for old in shots.glob("*.png"):
        old.unlink()
    return Session(page, problems, shots, base_url)

"""Security headers, the browser page's CSP, /docs without a CDN, /readyz without the database type."""

from __future__ import annotations

import re

import httpx

from app.api.security_headers import PAGE_CSP
from app.settings import Settings
from tests.browser.conftest import STRICT_CSP


def test_page_has_nosniff_frame_ancestors_and_the_csp_the_browser_tests_pass(
    client: httpx.Client,
) -> None:
    response = client.get("/")
    assert response.status_code == 200
    assert response.headers["x-content-type-options"] == "nosniff"
    assert response.headers["x-frame-options"] == "DENY"
    csp = response.headers["content-security-policy"]
    assert csp == PAGE_CSP
    # the browser tests drive the page under this policy and fail on any violation
    assert csp == STRICT_CSP
    assert "frame-ancestors 'none'" in csp
    assert "unsafe-inline" not in csp


def test_every_response_is_nosniff_and_unframeable(
    client: httpx.Client, auth: dict[str, str]
) -> None:
    for response in (
        client.get("/courts", headers=auth),
        client.get("/courts"),  # an error
        client.get("/static/app.js"),
        client.get("/openapi.json"),
    ):
        assert response.headers["x-content-type-options"] == "nosniff"
        assert "frame-ancestors 'none'" in response.headers["content-security-policy"]


def test_docs_are_served_locally(client: httpx.Client) -> None:
    page = client.get("/docs")
    assert page.status_code == 200
    assert "script-src 'self';" in page.headers["content-security-policy"]
    sources = re.findall(r'(?:src|href)="([^"]+)"', page.text)
    assert sources and all(s.startswith("/") for s in sources), sources  # nothing off-site
    assert "<script>" not in page.text  # no inline script
    for source in sources:
        asset = client.get(source)
        assert asset.status_code == 200, source
        assert len(asset.content) > 100
    bundle = client.get("/docs/assets/swagger-ui-bundle.js")
    assert bundle.headers["content-type"].startswith("text/javascript")
    assert client.get("/docs/assets/..%2F..%2Fsettings.py").status_code == 404
    assert client.get("/redoc").status_code == 404  # FastAPI's CDN-backed page is off


def test_readyz_does_not_disclose_the_database(client: httpx.Client, settings: Settings) -> None:
    body = client.get("/readyz").json()
    assert set(body) == {"status", "revision"}
    assert "sqlite" not in client.get("/readyz").text.lower()

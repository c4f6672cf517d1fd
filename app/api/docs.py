"""The interactive API reference at /docs, served entirely by this server.

FastAPI's default /docs loads Swagger UI from a public CDN: a third party's script running with
the page's access, and no docs at all where the CDN is unreachable. The Swagger UI files come from
the `fastapi-offline` package instead, and the page's one script of our own is a file, so /docs
runs under a CSP without 'unsafe-inline' scripts.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from fastapi import APIRouter
from fastapi.responses import FileResponse, HTMLResponse

from app.api.errors import ApiError
from app.api.routing import ApiRoute

SWAGGER_DIR = Path(str(resources.files("fastapi_offline") / "static"))
INIT_SCRIPT = Path(__file__).resolve().parents[1] / "static" / "docs" / "init.js"
DOCS_ASSETS = {
    "swagger-ui-bundle.js": (SWAGGER_DIR / "swagger-ui-bundle.js", "text/javascript"),
    "swagger-ui.css": (SWAGGER_DIR / "swagger-ui.css", "text/css"),
    "init.js": (INIT_SCRIPT, "text/javascript"),
}
# Swagger UI sets style attributes and draws icons from data: URIs; scripts stay 'self' only
DOCS_CSP = (
    "default-src 'self'; script-src 'self'; style-src 'self' 'unsafe-inline'; "
    "img-src 'self' data:; connect-src 'self'; object-src 'none'; base-uri 'none'; "
    "frame-ancestors 'none'"
)
DOCS_HTML = """<!doctype html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>squashcal API</title>
<link rel="icon" href="/static/favicon.svg" type="image/svg+xml">
<link rel="stylesheet" href="/docs/assets/swagger-ui.css">
</head>
<body>
<div id="swagger-ui"></div>
<script src="/docs/assets/swagger-ui-bundle.js"></script>
<script src="/docs/assets/init.js"></script>
</body>
</html>
"""

router = APIRouter(include_in_schema=False, route_class=ApiRoute)


@router.get("/docs")
def docs_page() -> HTMLResponse:
    return HTMLResponse(DOCS_HTML, headers={"Content-Security-Policy": DOCS_CSP})


@router.get("/docs/assets/{name}")
def docs_asset(name: str) -> FileResponse:
    asset = DOCS_ASSETS.get(name)
    if asset is None:
        raise ApiError(404, "not_found", f"no docs asset {name!r}")
    path, media_type = asset
    return FileResponse(path, media_type=media_type, headers={"Cache-Control": "max-age=86400"})

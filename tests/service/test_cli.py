"""`squashcal migrate` and `squashcal keys ...` as a user runs them."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import httpx

from app.db import repo
from app.db.migrate import head_revision
from app.db.session import make_engine, make_sessionmaker
from tests.service.conftest import make_settings
from tests.service.test_e2e import free_port

REPO_ROOT = Path(__file__).resolve().parents[2]


def squashcal(
    data_dir: Path, *args: str, timeout_s: float = 120
) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "SQUASHCAL_DATA_DIR": str(data_dir), "SQUASHCAL_WARM_UP": "0"}
    return subprocess.run(
        [sys.executable, "-m", "app.cli", *args],
        cwd=REPO_ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout_s,
    )


def test_migrate_and_manage_keys(tmp_path: Path) -> None:
    data_dir = tmp_path / "data"
    migrated = squashcal(data_dir, "migrate")
    assert migrated.returncode == 0, migrated.stderr
    assert f"revision {head_revision(make_settings(data_dir))}" in migrated.stdout

    created = squashcal(data_dir, "keys", "create", "--name", "coach app")
    assert created.returncode == 0, created.stderr
    key = created.stdout.strip().splitlines()[-1]
    assert key.startswith("sqc_") and len(key) > 40

    settings = make_settings(data_dir)
    engine = make_engine(settings)
    with make_sessionmaker(engine)() as session:
        tenant_id = repo.tenant_for_key(session, key)
        [row] = repo.list_api_keys(session)
    engine.dispose()
    assert tenant_id is not None and row.tenant_id == tenant_id

    second = squashcal(data_dir, "keys", "create", "--name", "second", "--tenant", tenant_id)
    assert second.returncode == 0, second.stderr
    listed = squashcal(data_dir, "keys", "list")
    assert listed.returncode == 0
    assert row.id in listed.stdout and "coach app" in listed.stdout
    assert key not in listed.stdout  # keys are never shown again

    assert squashcal(data_dir, "keys", "revoke", row.id).returncode == 0
    again = squashcal(data_dir, "keys", "revoke", row.id)
    assert again.returncode == 1 and "no active key" in again.stderr
    unknown_tenant = squashcal(data_dir, "keys", "create", "--name", "x", "--tenant", "nope")
    assert unknown_tenant.returncode == 1 and "no tenant" in unknown_tenant.stderr


def test_commands_on_a_never_migrated_data_dir_say_what_to_run(tmp_path: Path) -> None:
    data_dir = tmp_path / "fresh"
    serve = ("serve", "--port", str(free_port()))  # a server would run until the timeout
    for args in (("keys", "list"), ("keys", "create", "--name", "x"), ("worker", "--once"), serve):
        result = squashcal(data_dir, *args, timeout_s=60)
        assert result.returncode == 2, (args, result.stdout, result.stderr)
        assert "run `squashcal migrate` first" in result.stderr
        assert "Traceback" not in result.stderr and "sqlalchemy" not in result.stderr.lower()
    assert squashcal(data_dir, "migrate").returncode == 0
    assert squashcal(data_dir, "keys", "list").returncode == 0


def test_serve_starts_while_the_database_is_unreachable(tmp_path: Path) -> None:
    """A database still starting (or restarted) does not stop the API: it answers 503 with
    Retry-After until the database is back (test_database_outage), and /readyz says why."""
    port = free_port()
    env = {
        **os.environ,
        "SQUASHCAL_DATA_DIR": str(tmp_path / "data"),
        "SQUASHCAL_WARM_UP": "0",
        # nothing listens on port 1: connections are refused at once
        "SQUASHCAL_DATABASE_URL": "postgresql+psycopg://postgres@127.0.0.1:1/test",
    }
    log = tmp_path / "serve.log"
    with log.open("wb") as out:
        process = subprocess.Popen(
            [sys.executable, "-m", "app.cli", "serve", "--port", str(port)],
            cwd=REPO_ROOT,
            env=env,
            stdout=out,
            stderr=subprocess.STDOUT,
        )
    try:
        deadline = time.monotonic() + 60
        while True:
            assert process.poll() is None, log.read_text()
            try:
                ready = httpx.get(f"http://127.0.0.1:{port}/readyz", timeout=5)
                break
            except httpx.TransportError:
                assert time.monotonic() < deadline, "the API did not start"
                time.sleep(0.2)
        assert ready.status_code == 503
        assert ready.json()["error"]["code"] == "database_unreachable"
    finally:
        process.terminate()
        process.wait(30)

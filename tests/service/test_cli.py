"""`squashcal migrate` and `squashcal keys ...` as a user runs them."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from app.db import repo
from app.db.migrate import head_revision
from app.db.session import make_engine, make_sessionmaker
from tests.service.conftest import make_settings

REPO_ROOT = Path(__file__).resolve().parents[2]


def squashcal(data_dir: Path, *args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "SQUASHCAL_DATA_DIR": str(data_dir)}
    return subprocess.run(
        [sys.executable, "-m", "app.cli", *args],
        cwd=REPO_ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
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
    for args in (("keys", "list"), ("keys", "create", "--name", "x"), ("worker", "--once")):
        result = squashcal(data_dir, *args)
        assert result.returncode == 2, (args, result.stdout, result.stderr)
        assert "run `squashcal migrate` first" in result.stderr
        assert "Traceback" not in result.stderr and "sqlalchemy" not in result.stderr.lower()
    assert squashcal(data_dir, "migrate").returncode == 0
    assert squashcal(data_dir, "keys", "list").returncode == 0

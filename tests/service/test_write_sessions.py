"""The API's transactions that read and then write (an upload's limits check and count, a new
court, the active camera) must not fail because another process committed in between. On
SQLite a transaction that began reading cannot take the write lock once another connection has
committed since its snapshot: SQLite answers "database is locked" at once, without waiting out
the busy timeout, and the API would answer 503 (seen under load: a coach's upload refused while
the worker was finishing a job). The API's write sessions take the lock at BEGIN instead."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest
from sqlalchemy import func, select
from sqlalchemy.exc import OperationalError
from sqlalchemy.orm import Session, sessionmaker

from app.db import repo
from app.db.models import Court
from app.main import create_app
from app.settings import Settings
from tests.service.conftest import migrated_settings

# how long the first transaction gives the other one to commit before it writes
OTHER_COMMIT_WAIT_S = 1.0


def _read_then_write_around_another_commit(sessions: sessionmaker[Session], tenant_id: str) -> int:
    """Read in one transaction, let another one add a court meanwhile, then add a court in the
    first; the courts stored at the end."""
    other_error: list[BaseException] = []

    def other() -> None:
        try:
            with sessions.begin() as session:
                repo.create_court(session, tenant_id, "other", "wsf")
        except BaseException as exc:  # noqa: BLE001 - reported by the test
            other_error.append(exc)

    with sessions.begin() as session:
        session.scalar(select(func.count(Court.id)))
        thread = threading.Thread(target=other)
        thread.start()
        # with the write lock taken at BEGIN, the other transaction waits for this one
        thread.join(OTHER_COMMIT_WAIT_S)
        repo.create_court(session, tenant_id, "first", "wsf")
    thread.join()
    assert other_error == []
    with sessions() as session:
        return int(session.scalar(select(func.count(Court.id))) or 0)


@pytest.fixture
def sqlite_settings(tmp_path: Path) -> Settings:
    return migrated_settings(tmp_path / "data", None)


def _tenant(sessions: sessionmaker[Session]) -> str:
    with sessions.begin() as session:
        key, _ = repo.create_api_key(session, name="coach")
        return key.tenant_id


def test_the_apis_write_sessions_survive_a_commit_between_their_read_and_write(
    sqlite_settings: Settings,
) -> None:
    state = create_app(sqlite_settings).state.squashcal
    tenant_id = _tenant(state.write_sessions)
    assert _read_then_write_around_another_commit(state.write_sessions, tenant_id) == 2


def test_a_plain_session_that_reads_first_is_refused_the_write_lock(
    sqlite_settings: Settings,
) -> None:
    # what the write sessions are for: the same transactions on the read sessions fail at once
    state = create_app(sqlite_settings).state.squashcal
    tenant_id = _tenant(state.sessions)
    with pytest.raises(OperationalError, match="locked"):
        _read_then_write_around_another_commit(state.sessions, tenant_id)

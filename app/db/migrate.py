"""Alembic from code: the config points at the repository's alembic/ and the service settings."""

from __future__ import annotations

from pathlib import Path

from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import Engine

from app.settings import Settings


def _repo_root() -> Path:
    # The working directory first (Docker image, `make run`), then the source checkout of `app`.
    for root in (Path.cwd(), Path(__file__).resolve().parents[2]):
        if (root / "alembic.ini").is_file() and (root / "alembic" / "env.py").is_file():
            return root
    raise FileNotFoundError(
        "cannot find alembic.ini and alembic/ (run from the repository root or the image's workdir)"
    )


def alembic_config(settings: Settings) -> Config:
    root = _repo_root()
    config = Config(str(root / "alembic.ini"))
    config.set_main_option("script_location", str(root / "alembic"))
    config.attributes["settings"] = settings
    config.attributes["configure_logging"] = False
    return config


def upgrade_head(settings: Settings) -> str | None:
    """Apply all migrations; returns the revision the database is at afterwards."""
    settings.data_dir.mkdir(parents=True, exist_ok=True)
    config = alembic_config(settings)
    command.upgrade(config, "head")
    return head_revision(settings)


def head_revision(settings: Settings) -> str | None:
    return ScriptDirectory.from_config(alembic_config(settings)).get_current_head()


def current_revision(engine: Engine) -> str | None:
    with engine.connect() as conn:
        return MigrationContext.configure(conn).get_current_revision()


def schema_problem(settings: Settings, unreachable_ok: bool = False) -> str | None:
    """Why the database cannot serve this code yet (a sentence saying what to run), else None
    (also when the database cannot be reached and `unreachable_ok`).

    Commands that read or write tables check this first, so a fresh data directory gets advice
    instead of a SQLAlchemy traceback.
    """
    from sqlalchemy.engine import make_url

    from app.db.session import make_engine

    where = make_url(settings.sqlalchemy_url).render_as_string(hide_password=True)
    engine = make_engine(settings)
    try:
        revision = current_revision(engine)
    except Exception as exc:
        if unreachable_ok:
            return None
        return f"cannot reach the database at {where} ({type(exc).__name__}): is it running?"
    finally:
        engine.dispose()
    head = head_revision(settings)
    if revision is None:
        return f"the database at {where} has no tables yet: run `squashcal migrate` first"
    if revision != head:
        return (
            f"the database at {where} is at schema revision {revision}, this code needs {head}: "
            "run `squashcal migrate` first"
        )
    return None

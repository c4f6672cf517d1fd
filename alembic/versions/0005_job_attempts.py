"""job_attempts: one row per claim of a job (worker, claimed, ended, outcome), written by the queue
in the claim's and the ending's transactions. Jobs claimed before this revision have no rows: their
earlier attempts were never recorded.

Revision ID: 0005
Revises: 0004
Create Date: 2026-11-30
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0005"
down_revision: str | None = "0004"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

# Frozen copy of the AttemptOutcome values at this revision (a later change needs its own migration).
OUTCOMES = ("succeeded", "failed", "failed_retry", "released", "lease_lost")
UTC_TIME = sa.DateTime(timezone=True)
OPEN = sa.text("ended_at IS NULL")


def _in(column: str, values: tuple[str, ...]) -> str:
    return f"{column} IN ({', '.join(repr(v) for v in values)})"


def upgrade() -> None:
    op.create_table(
        "job_attempts",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("job_id", sa.String(length=32), nullable=False),
        sa.Column("attempt", sa.Integer(), nullable=False),
        sa.Column("worker_id", sa.String(length=200), nullable=False),
        sa.Column("claimed_at", UTC_TIME, nullable=False),
        sa.Column("ended_at", UTC_TIME, nullable=True),
        sa.Column("outcome", sa.String(length=16), nullable=True),
        sa.Column("error_code", sa.String(length=64), nullable=True),
        sa.ForeignKeyConstraint(
            ["job_id"], ["jobs.id"], name="fk_job_attempts_job_id_jobs", ondelete="CASCADE"
        ),
        sa.PrimaryKeyConstraint("id", name="pk_job_attempts"),
        # op.f: the names are final (the models' naming convention would prefix "ck_<table>_"
        # to them a second time)
        sa.CheckConstraint(_in("outcome", OUTCOMES), name=op.f("ck_job_attempts_outcome")),
        sa.CheckConstraint(
            "(ended_at IS NULL) = (outcome IS NULL)",
            name=op.f("ck_job_attempts_ended_with_outcome"),
        ),
    )
    op.create_index("ix_job_attempts_job_id", "job_attempts", ["job_id"])
    op.create_index(
        "ix_job_attempts_one_open_per_job",
        "job_attempts",
        ["job_id"],
        unique=True,
        sqlite_where=OPEN,
        postgresql_where=OPEN,
    )


def downgrade() -> None:
    op.drop_index("ix_job_attempts_one_open_per_job", table_name="job_attempts")
    op.drop_index("ix_job_attempts_job_id", table_name="job_attempts")
    op.drop_table("job_attempts")

"""job status and stage: only the values of the JobStatus / JobStage enums (CHECK constraints)

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-30
"""

from collections.abc import Sequence

from alembic import op

revision: str = "0003"
down_revision: str | None = "0002"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

# Frozen copies of the values at this revision (a later enum change needs its own migration).
STATUSES = ("queued", "running", "succeeded", "failed")
STAGES = ("queued", "background", "edges", "optimising", "refining", "storing", "done")


def _in(column: str, values: tuple[str, ...]) -> str:
    return f"{column} IN ({', '.join(repr(v) for v in values)})"


def upgrade() -> None:
    with op.batch_alter_table("jobs") as batch:
        batch.create_check_constraint("ck_jobs_status", _in("status", STATUSES))
        batch.create_check_constraint("ck_jobs_stage", _in("stage", STAGES))


def downgrade() -> None:
    with op.batch_alter_table("jobs") as batch:
        batch.drop_constraint("ck_jobs_stage", type_="check")
        batch.drop_constraint("ck_jobs_status", type_="check")

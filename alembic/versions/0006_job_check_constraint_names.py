"""jobs' CHECK constraints get the names the models give them: 0003 created them as
"ck_jobs_ck_jobs_status" and "ck_jobs_ck_jobs_stage" (the naming convention prefixed its own
"ck_jobs_" to names that already had it), so an operator's error message or a later migration
naming "ck_jobs_status" found nothing.

Revision ID: 0006
Revises: 0005
Create Date: 2026-12-01
"""

from collections.abc import Sequence

from alembic import op

revision: str = "0006"
down_revision: str | None = "0005"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

# Frozen copies of the values at this revision (a later enum change needs its own migration).
STATUSES = ("queued", "running", "succeeded", "failed")
STAGES = ("queued", "background", "edges", "optimising", "refining", "storing", "done")
# (column, values, name 0003 gave, name the models give); op.f: names taken as they are
CHECKS = (
    ("status", STATUSES, "ck_jobs_ck_jobs_status", "ck_jobs_status"),
    ("stage", STAGES, "ck_jobs_ck_jobs_stage", "ck_jobs_stage"),
)


def _in(column: str, values: tuple[str, ...]) -> str:
    return f"{column} IN ({', '.join(repr(v) for v in values)})"


def _rename(old_index: int, new_index: int) -> None:
    with op.batch_alter_table("jobs") as batch:
        for check in CHECKS:
            batch.drop_constraint(op.f(check[old_index]), type_="check")
            batch.create_check_constraint(op.f(check[new_index]), _in(check[0], check[1]))


def upgrade() -> None:
    _rename(2, 3)


def downgrade() -> None:
    _rename(3, 2)

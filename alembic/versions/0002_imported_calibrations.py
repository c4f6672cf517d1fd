"""imported calibrations: a calibration may come without a job (an imported camera) and without
a fitness (nothing was fitted)

Revision ID: 0002
Revises: 0001
Create Date: 2026-11-30
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0002"
down_revision: str | None = "0001"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("calibrations") as batch:
        batch.alter_column("job_id", existing_type=sa.String(length=32), nullable=True)
        batch.alter_column("fitness", existing_type=sa.Float(), nullable=True)


def downgrade() -> None:
    # imported calibrations have no job to point at: they cannot exist in the old schema
    op.execute("DELETE FROM calibrations WHERE job_id IS NULL")
    with op.batch_alter_table("calibrations") as batch:
        batch.alter_column("fitness", existing_type=sa.Float(), nullable=False)
        batch.alter_column("job_id", existing_type=sa.String(length=32), nullable=False)

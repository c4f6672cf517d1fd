"""upload_attempts: every upload the API began to receive, whatever became of it. The upload rate
(max_uploads_per_hour_per_tenant) counted jobs, so uploads refused for their content (a text file
named .png, a 1x1 image) were never counted and a client sending them in a loop was not held to
it. Filled from the jobs, so that a tenant's hour does not start again at the upgrade.

Revision ID: 0008
Revises: 0007
Create Date: 2026-12-07
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0008"
down_revision: str | None = "0007"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "upload_attempts",
        sa.Column("id", sa.String(length=32), nullable=False),
        sa.Column("tenant_id", sa.String(length=32), nullable=False),
        sa.Column("received_at", sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(
            ["tenant_id"],
            ["tenants.id"],
            name=op.f("fk_upload_attempts_tenant_id_tenants"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_upload_attempts")),
    )
    op.create_index(
        "ix_upload_attempts_tenant_time", "upload_attempts", ["tenant_id", "received_at"]
    )
    op.execute(
        "INSERT INTO upload_attempts (id, tenant_id, received_at) "
        "SELECT id, tenant_id, created_at FROM jobs"
    )


def downgrade() -> None:
    op.drop_index("ix_upload_attempts_tenant_time", table_name="upload_attempts")
    op.drop_table("upload_attempts")

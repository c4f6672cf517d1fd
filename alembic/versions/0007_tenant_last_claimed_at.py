"""tenants: last_claimed_at, when a worker last took one of the tenant's jobs. The queue's claims
take turns across tenants by it (fewest running jobs first, then the tenant served longest ago),
so that one worker finishing a tenant's jobs one by one does not serve that tenant's whole pile
before another tenant's single upload. Filled from the jobs already claimed.

Revision ID: 0007
Revises: 0006
Create Date: 2026-12-02
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0007"
down_revision: str | None = "0006"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("tenants") as batch:
        batch.add_column(sa.Column("last_claimed_at", sa.DateTime(timezone=True), nullable=True))
    # a claim sets started_at: the latest one of a tenant's jobs is its last turn
    op.execute(
        "UPDATE tenants SET last_claimed_at = "
        "(SELECT max(jobs.started_at) FROM jobs WHERE jobs.tenant_id = tenants.id)"
    )


def downgrade() -> None:
    with op.batch_alter_table("tenants") as batch:
        batch.drop_column("last_claimed_at")

"""Passes from data: a pass may come from the telemetry itself (origin 'data', station unknown or given).

Revision ID: 0002
Revises: 0001
Create Date: 2026-12-01 23:00:00

"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0002"
down_revision: str | Sequence[str] | None = "0001"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    """Add pass.origin ('predicted' | 'data'); a pass from data may have no station and no elevation."""
    with op.batch_alter_table("pass", schema=None) as batch_op:
        batch_op.add_column(sa.Column("origin", sa.String(length=16), nullable=False, server_default="predicted"))
        batch_op.alter_column("station_id", existing_type=sa.Integer(), nullable=True)
        batch_op.alter_column("max_elevation_deg", existing_type=sa.Float(), nullable=True)


def downgrade() -> None:
    """Drop passes from data and the origin column."""
    op.execute("DELETE FROM pass WHERE origin = 'data'")
    with op.batch_alter_table("pass", schema=None) as batch_op:
        batch_op.alter_column("station_id", existing_type=sa.Integer(), nullable=False)
        batch_op.alter_column("max_elevation_deg", existing_type=sa.Float(), nullable=False)
        batch_op.drop_column("origin")

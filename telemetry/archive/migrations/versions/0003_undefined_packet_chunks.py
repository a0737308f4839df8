"""Raw packets of APIDs the dictionary did not define, kept for a later definition (issue 12).

Revision ID: 0003
Revises: 0002
Create Date: 2026-12-01 22:45:00

"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0003"
down_revision: str | Sequence[str] | None = "0002"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    """Upgrade schema."""
    op.create_table(
        "undefined_packet_chunk",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("satellite_id", sa.Integer(), nullable=False),
        sa.Column("upload_id", sa.Integer(), nullable=False),
        sa.Column("apid", sa.Integer(), nullable=False),
        sa.Column("n_packets", sa.Integer(), nullable=False),
        sa.Column("seq_blob", sa.LargeBinary(), nullable=False),
        sa.Column("length_blob", sa.LargeBinary(), nullable=False),
        sa.Column("raw_blob", sa.LargeBinary(), nullable=False),
        sa.ForeignKeyConstraint(
            ["satellite_id"], ["satellite.id"], name=op.f("fk_undefined_packet_chunk_satellite_id_satellite")
        ),
        sa.ForeignKeyConstraint(["upload_id"], ["upload.id"], name=op.f("fk_undefined_packet_chunk_upload_id_upload")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_undefined_packet_chunk")),
    )
    with op.batch_alter_table("undefined_packet_chunk", schema=None) as batch_op:
        batch_op.create_index("ix_undefined_packet_chunk_apid", ["satellite_id", "apid"], unique=False)


def downgrade() -> None:
    """Downgrade schema."""
    with op.batch_alter_table("undefined_packet_chunk", schema=None) as batch_op:
        batch_op.drop_index("ix_undefined_packet_chunk_apid")
    op.drop_table("undefined_packet_chunk")

"""Initial archive schema: satellites, stations, TLEs, passes, uploads, packet/value chunks, alarms.

Revision ID: 0001
Revises: (none)
Create Date: 2026-11-23 05:58:34.906570

"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

# revision identifiers, used by Alembic.
revision: str = "0001"
down_revision: str | Sequence[str] | None = None
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    """Upgrade schema."""
    op.create_table(
        "ground_station",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=64), nullable=False),
        sa.Column("lat_deg", sa.Float(), nullable=False),
        sa.Column("lon_deg", sa.Float(), nullable=False),
        sa.Column("alt_m", sa.Float(), nullable=False),
        sa.Column("min_elevation_deg", sa.Float(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_ground_station")),
        sa.UniqueConstraint("name", name=op.f("uq_ground_station_name")),
    )
    op.create_table(
        "satellite",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=64), nullable=False),
        sa.Column("norad_id", sa.Integer(), nullable=True),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_satellite")),
        sa.UniqueConstraint("name", name=op.f("uq_satellite_name")),
    )
    op.create_table(
        "alarm",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("satellite_id", sa.Integer(), nullable=False),
        sa.Column("parameter", sa.String(length=128), nullable=False),
        sa.Column("state", sa.String(length=16), nullable=False),
        sa.Column("severity", sa.String(length=8), nullable=False),
        sa.Column("level", sa.Integer(), nullable=False),
        sa.Column("first_t_ns", sa.BigInteger(), nullable=False),
        sa.Column("last_t_ns", sa.BigInteger(), nullable=False),
        sa.Column("acknowledged_by", sa.String(length=64), nullable=True),
        sa.Column("shelved_until_ns", sa.BigInteger(), nullable=True),
        sa.ForeignKeyConstraint(["satellite_id"], ["satellite.id"], name=op.f("fk_alarm_satellite_id_satellite")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_alarm")),
    )
    with op.batch_alter_table("alarm", schema=None) as batch_op:
        batch_op.create_index("ix_alarm_state", ["satellite_id", "state"], unique=False)

    op.create_table(
        "parameter",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("satellite_id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=128), nullable=False),
        sa.Column("apid", sa.Integer(), nullable=False),
        sa.ForeignKeyConstraint(["satellite_id"], ["satellite.id"], name=op.f("fk_parameter_satellite_id_satellite")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_parameter")),
        sa.UniqueConstraint("satellite_id", "name", name=op.f("uq_parameter_satellite_id")),
    )
    op.create_table(
        "tle",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("satellite_id", sa.Integer(), nullable=False),
        sa.Column("epoch_ns", sa.BigInteger(), nullable=False),
        sa.Column("line1", sa.String(length=80), nullable=False),
        sa.Column("line2", sa.String(length=80), nullable=False),
        sa.ForeignKeyConstraint(["satellite_id"], ["satellite.id"], name=op.f("fk_tle_satellite_id_satellite")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_tle")),
        sa.UniqueConstraint("satellite_id", "epoch_ns", name=op.f("uq_tle_satellite_id")),
    )
    op.create_table(
        "upload",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("satellite_id", sa.Integer(), nullable=False),
        sa.Column("uploaded_by", sa.String(length=64), nullable=False),
        sa.Column("uploaded_at_ns", sa.BigInteger(), nullable=False),
        sa.Column("source", sa.String(length=512), nullable=False),
        sa.Column("sha256", sa.String(length=64), nullable=False),
        sa.Column("packets_accepted", sa.Integer(), nullable=False),
        sa.Column("samples_accepted", sa.BigInteger(), nullable=False),
        sa.Column("report_json", sa.Text(), nullable=False),
        sa.ForeignKeyConstraint(["satellite_id"], ["satellite.id"], name=op.f("fk_upload_satellite_id_satellite")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_upload")),
        sa.UniqueConstraint("satellite_id", "sha256", name=op.f("uq_upload_satellite_id")),
    )
    op.create_table(
        "alarm_event",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("alarm_id", sa.Integer(), nullable=False),
        sa.Column("upload_id", sa.Integer(), nullable=True),
        sa.Column("t_ns", sa.BigInteger(), nullable=False),
        sa.Column("kind", sa.String(length=16), nullable=False),
        sa.Column("severity", sa.String(length=8), nullable=True),
        sa.Column("value", sa.Float(), nullable=True),
        sa.Column("actor", sa.String(length=64), nullable=True),
        sa.ForeignKeyConstraint(["alarm_id"], ["alarm.id"], name=op.f("fk_alarm_event_alarm_id_alarm")),
        sa.ForeignKeyConstraint(["upload_id"], ["upload.id"], name=op.f("fk_alarm_event_upload_id_upload")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_alarm_event")),
    )
    with op.batch_alter_table("alarm_event", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_alarm_event_alarm_id"), ["alarm_id"], unique=False)

    op.create_table(
        "packet_chunk",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("satellite_id", sa.Integer(), nullable=False),
        sa.Column("upload_id", sa.Integer(), nullable=False),
        sa.Column("apid", sa.Integer(), nullable=False),
        sa.Column("t_start_ns", sa.BigInteger(), nullable=False),
        sa.Column("t_end_ns", sa.BigInteger(), nullable=False),
        sa.Column("n_packets", sa.Integer(), nullable=False),
        sa.Column("t_blob", sa.LargeBinary(), nullable=False),
        sa.Column("seq_blob", sa.LargeBinary(), nullable=False),
        sa.Column("length_blob", sa.LargeBinary(), nullable=False),
        sa.Column("raw_blob", sa.LargeBinary(), nullable=False),
        sa.ForeignKeyConstraint(
            ["satellite_id"], ["satellite.id"], name=op.f("fk_packet_chunk_satellite_id_satellite")
        ),
        sa.ForeignKeyConstraint(["upload_id"], ["upload.id"], name=op.f("fk_packet_chunk_upload_id_upload")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_packet_chunk")),
    )
    with op.batch_alter_table("packet_chunk", schema=None) as batch_op:
        batch_op.create_index("ix_packet_chunk_span", ["satellite_id", "apid", "t_start_ns", "t_end_ns"], unique=False)
        batch_op.create_index(batch_op.f("ix_packet_chunk_upload_id"), ["upload_id"], unique=False)

    op.create_table(
        "pass",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("satellite_id", sa.Integer(), nullable=False),
        sa.Column("station_id", sa.Integer(), nullable=False),
        sa.Column("tle_id", sa.Integer(), nullable=True),
        sa.Column("aos_ns", sa.BigInteger(), nullable=False),
        sa.Column("los_ns", sa.BigInteger(), nullable=False),
        sa.Column("max_elevation_ns", sa.BigInteger(), nullable=False),
        sa.Column("max_elevation_deg", sa.Float(), nullable=False),
        sa.Column("received_start_ns", sa.BigInteger(), nullable=True),
        sa.Column("received_end_ns", sa.BigInteger(), nullable=True),
        sa.Column("packets_received", sa.Integer(), nullable=False),
        sa.Column("packets_missing", sa.Integer(), nullable=False),
        sa.ForeignKeyConstraint(["satellite_id"], ["satellite.id"], name=op.f("fk_pass_satellite_id_satellite")),
        sa.ForeignKeyConstraint(["station_id"], ["ground_station.id"], name=op.f("fk_pass_station_id_ground_station")),
        sa.ForeignKeyConstraint(["tle_id"], ["tle.id"], name=op.f("fk_pass_tle_id_tle")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_pass")),
        sa.UniqueConstraint("satellite_id", "station_id", "aos_ns", name=op.f("uq_pass_satellite_id")),
    )
    with op.batch_alter_table("pass", schema=None) as batch_op:
        batch_op.create_index("ix_pass_span", ["satellite_id", "aos_ns", "los_ns"], unique=False)

    op.create_table(
        "value_chunk",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("parameter_id", sa.Integer(), nullable=False),
        sa.Column("chunk_id", sa.Integer(), nullable=False),
        sa.Column("dtype", sa.String(length=8), nullable=False),
        sa.Column("v_min", sa.Float(), nullable=True),
        sa.Column("v_max", sa.Float(), nullable=True),
        sa.Column("v_blob", sa.LargeBinary(), nullable=False),
        sa.ForeignKeyConstraint(["chunk_id"], ["packet_chunk.id"], name=op.f("fk_value_chunk_chunk_id_packet_chunk")),
        sa.ForeignKeyConstraint(["parameter_id"], ["parameter.id"], name=op.f("fk_value_chunk_parameter_id_parameter")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_value_chunk")),
        sa.UniqueConstraint("parameter_id", "chunk_id", name=op.f("uq_value_chunk_parameter_id")),
    )
    with op.batch_alter_table("value_chunk", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_value_chunk_chunk_id"), ["chunk_id"], unique=False)


def downgrade() -> None:
    """Downgrade schema."""
    with op.batch_alter_table("value_chunk", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_value_chunk_chunk_id"))

    op.drop_table("value_chunk")
    with op.batch_alter_table("pass", schema=None) as batch_op:
        batch_op.drop_index("ix_pass_span")

    op.drop_table("pass")
    with op.batch_alter_table("packet_chunk", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_packet_chunk_upload_id"))
        batch_op.drop_index("ix_packet_chunk_span")

    op.drop_table("packet_chunk")
    with op.batch_alter_table("alarm_event", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_alarm_event_alarm_id"))

    op.drop_table("alarm_event")
    op.drop_table("upload")
    op.drop_table("tle")
    op.drop_table("parameter")
    with op.batch_alter_table("alarm", schema=None) as batch_op:
        batch_op.drop_index("ix_alarm_state")

    op.drop_table("alarm")
    op.drop_table("satellite")
    op.drop_table("ground_station")

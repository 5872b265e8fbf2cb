"""Schema 1: packs, their source files (raw bytes in blobs) and events.

Revision ID: 0001
Revises: none
"""

import sqlalchemy as sa
from alembic import op

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None

EVENT_FLOATS = (
    "duration_s", "discharged_Ah", "discharged_Wh", "mean_current_A", "max_current_A",
    "rest_voltage_V", "rest_after_V", "rest_after_s", "min_voltage_V", "end_voltage_V",
    "end_current_A", "resistance_ohm", "resistance_low_ohm", "resistance_high_ohm",
    "temperature_start_C", "temperature_max_C", "ambient_C",
)


def upgrade() -> None:
    meta = op.create_table(
        "logbook_meta",
        sa.Column("key", sa.String(64), primary_key=True),
        sa.Column("value", sa.Text, nullable=False),
    )
    op.create_table(
        "packs",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("name", sa.String(200), nullable=False, unique=True),
        sa.Column("label_capacity_Ah", sa.Float),
        sa.Column("chemistry", sa.String(20)),
        sa.Column("cells", sa.Integer),
        sa.Column("created_at", sa.String(40), nullable=False),
    )
    op.create_table(
        "blobs",
        sa.Column("sha256", sa.String(64), primary_key=True),
        sa.Column("compression", sa.String(10), nullable=False),
        sa.Column("size_bytes", sa.BigInteger, nullable=False),
        sa.Column("data", sa.LargeBinary, nullable=False),
    )
    op.create_table(
        "sources",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("sha256", sa.String(64), nullable=False, unique=True),
        sa.Column("pack_id", sa.Integer, sa.ForeignKey("packs.id"), nullable=False),
        sa.Column("file_name", sa.String(500), nullable=False),
        sa.Column("path", sa.Text),
        sa.Column("size_bytes", sa.BigInteger, nullable=False),
        sa.Column("format", sa.String(40), nullable=False),
        sa.Column("added_at", sa.String(40), nullable=False),
        sa.Column("options_json", sa.Text, nullable=False),
        sa.Column("notes_json", sa.Text, nullable=False),
    )
    op.create_table(
        "events",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("source_id", sa.Integer, sa.ForeignKey("sources.id"), nullable=False),
        sa.Column("idx", sa.Integer, nullable=False),
        sa.Column("pack_id", sa.Integer, sa.ForeignKey("packs.id"), nullable=False),
        sa.Column("kind", sa.String(20), nullable=False),
        sa.Column("start_time", sa.String(40)),
        *[sa.Column(name, sa.Float) for name in EVENT_FLOATS],
        sa.Column("reaches_knee", sa.Boolean, nullable=False),
        sa.Column("cells", sa.Integer),
        sa.Column("samples", sa.Integer, nullable=False),
        sa.Column("curve_json", sa.Text, nullable=False),
        sa.UniqueConstraint("source_id", "idx", name="uq_events_source_idx"),
    )
    op.bulk_insert(meta, [{"key": "schema_version", "value": "1"}])


def downgrade() -> None:
    for table in ("events", "sources", "blobs", "packs", "logbook_meta"):
        op.drop_table(table)

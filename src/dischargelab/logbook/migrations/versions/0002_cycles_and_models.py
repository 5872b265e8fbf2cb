"""Schema 2: events.cycle (from the file name) and events.cell_spread_V; fitted models.

Revision ID: 0002
Revises: 0001
"""

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None

META = sa.table("logbook_meta", sa.column("key", sa.String), sa.column("value", sa.Text))


def upgrade() -> None:
    op.add_column("events", sa.Column("cycle", sa.Integer))
    op.add_column("events", sa.Column("cell_spread_V", sa.Float))
    op.create_table(
        "models",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("pack_id", sa.Integer, sa.ForeignKey("packs.id"), nullable=False),
        sa.Column("fitted_at", sa.String(40), nullable=False),
        sa.Column("reference_event_id", sa.Integer, sa.ForeignKey("events.id")),
        sa.Column("capacity_Ah", sa.Float),
        sa.Column("resistance_ohm", sa.Float),
        sa.Column("battery_json", sa.Text, nullable=False),
    )
    op.execute(META.update().where(META.c.key == "schema_version").values(value="2"))


def downgrade() -> None:
    op.drop_table("models")
    with op.batch_alter_table("events") as batch:
        batch.drop_column("cell_spread_V")
        batch.drop_column("cycle")
    op.execute(META.update().where(META.c.key == "schema_version").values(value="1"))

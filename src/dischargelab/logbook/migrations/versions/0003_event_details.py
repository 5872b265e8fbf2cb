"""Schema 3: events.details_json, an event's further figures (rests and their relaxation,
charges, per-cell figures, how well the sampling resolves the current), JSON.

Revision ID: 0003
Revises: 0002
"""

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None

META = sa.table("logbook_meta", sa.column("key", sa.String), sa.column("value", sa.Text))


def upgrade() -> None:
    op.add_column("events", sa.Column("details_json", sa.Text))
    op.execute(META.update().where(META.c.key == "schema_version").values(value="3"))


def downgrade() -> None:
    with op.batch_alter_table("events") as batch:
        batch.drop_column("details_json")
    op.execute(META.update().where(META.c.key == "schema_version").values(value="2"))

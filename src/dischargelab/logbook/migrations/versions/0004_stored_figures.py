"""Schema 4: a version per pack, raised by every write that changes the pack, and each
pack's figures (health, forecast, fleet row, model curves) stored with the version they
were computed from.

Revision ID: 0004
Revises: 0003
"""

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None

META = sa.table("logbook_meta", sa.column("key", sa.String), sa.column("value", sa.Text))


def upgrade() -> None:
    op.add_column("packs", sa.Column("version", sa.Integer, nullable=False,
                                     server_default="0"))
    op.create_table(
        "pack_figures",
        sa.Column("pack_id", sa.Integer, sa.ForeignKey("packs.id"), primary_key=True,
                  autoincrement=False),
        sa.Column("pack_version", sa.Integer, nullable=False),
        sa.Column("figures_version", sa.String(60), nullable=False),
        sa.Column("computed_at", sa.String(40), nullable=False),
        sa.Column("row_json", sa.Text),
        sa.Column("pack_json", sa.Text),
        sa.Column("fleet_json", sa.Text),
        sa.Column("health_json", sa.Text),
        sa.Column("model_json", sa.Text),
        sa.Column("error", sa.Text),
    )
    op.execute(META.update().where(META.c.key == "schema_version").values(value="4"))


def downgrade() -> None:
    op.drop_table("pack_figures")
    with op.batch_alter_table("packs") as batch:
        batch.drop_column("version")
    op.execute(META.update().where(META.c.key == "schema_version").values(value="3"))

"""one row per stock map: partial unique index on maps.name where is_stock

Two navdeck processes starting at once against one PostgreSQL both found a stock world missing and
both inserted it. Existing duplicates are merged first (runs pointing at a duplicate are repointed to
the oldest row, which is kept), then the index makes the race impossible (app.map_store.register_stock
treats the loser's unique violation as "already registered").

Revision ID: 0004
Revises: 0003
Create Date: 2026-11-22 05:10:00
"""

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None

KEEP = "SELECT MIN(k.id) FROM maps k WHERE k.is_stock GROUP BY k.name"


def upgrade() -> None:
    op.execute(
        f"""
        UPDATE runs SET map_id = (
            SELECT MIN(k.id) FROM maps k
            WHERE k.is_stock AND k.name = (SELECT d.name FROM maps d WHERE d.id = runs.map_id)
        )
        WHERE map_id IN (SELECT d.id FROM maps d WHERE d.is_stock AND d.id NOT IN ({KEEP}))
        """
    )
    op.execute(f"DELETE FROM maps WHERE is_stock AND id NOT IN ({KEEP})")
    op.create_index(
        "uq_maps_stock_name",
        "maps",
        ["name"],
        unique=True,
        sqlite_where=sa.text("is_stock"),
        postgresql_where=sa.text("is_stock"),
    )


def downgrade() -> None:
    op.drop_index("uq_maps_stock_name", table_name="maps")

"""places: named poses per map, goals by name (issue 19)

Revision ID: 0006
Revises: 0005
Create Date: 2026-11-26 09:30:00
"""

import sqlalchemy as sa
from alembic import op

revision = "0006"
down_revision = "0005"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "places",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("map_id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=100), nullable=False),
        sa.Column("x", sa.Float(), nullable=False),
        sa.Column("y", sa.Float(), nullable=False),
        sa.Column("theta", sa.Float(), nullable=False),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.ForeignKeyConstraint(["map_id"], ["maps.id"], ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id"),
    )
    op.create_index("ix_places_map_id", "places", ["map_id"], unique=False)
    op.create_index("uq_places_map_name", "places", ["map_id", "name"], unique=True)


def downgrade() -> None:
    op.drop_index("uq_places_map_name", table_name="places")
    op.drop_index("ix_places_map_id", table_name="places")
    op.drop_table("places")

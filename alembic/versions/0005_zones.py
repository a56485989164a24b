"""zones: keepout and speed-limit polygons per map (issue 19)

Revision ID: 0005
Revises: 0004
Create Date: 2026-11-26 09:10:00
"""

import sqlalchemy as sa
from alembic import op

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "zones",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("map_id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=100), nullable=False),
        sa.Column("kind", sa.String(length=20), nullable=False),
        sa.Column("polygon", sa.JSON(), nullable=False),
        sa.Column("speed_limit", sa.Float(), nullable=True),
        sa.Column("speed_limit_unit", sa.String(length=10), nullable=False, server_default="percent"),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.Column("updated_at", sa.DateTime(), nullable=False),
        sa.ForeignKeyConstraint(["map_id"], ["maps.id"], ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id"),
    )
    op.create_index("ix_zones_map_id", "zones", ["map_id"], unique=False)


def downgrade() -> None:
    op.drop_index("ix_zones_map_id", table_name="zones")
    op.drop_table("zones")

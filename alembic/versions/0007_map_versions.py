"""map versions: maps.parent_id (the version an edit was made from) and maps.version (issue 19)

Revision ID: 0007
Revises: 0006
Create Date: 2026-11-26 09:35:00
"""

import sqlalchemy as sa
from alembic import op

revision = "0007"
down_revision = "0006"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("maps", schema=None) as batch_op:
        batch_op.add_column(sa.Column("parent_id", sa.Integer(), nullable=True))
        batch_op.add_column(sa.Column("version", sa.Integer(), nullable=False, server_default="1"))
        batch_op.create_index("ix_maps_parent_id", ["parent_id"], unique=False)


def downgrade() -> None:
    with op.batch_alter_table("maps", schema=None) as batch_op:
        batch_op.drop_index("ix_maps_parent_id")
        batch_op.drop_column("version")
        batch_op.drop_column("parent_id")

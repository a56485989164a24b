"""runs: per-run samples, scans, plans, goals and map snapshots; run columns for listing

Revision ID: 0002
Revises: 0001
Create Date: 2026-11-22 01:55:00
"""

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def _chunk_table(name: str, extra: list[sa.Column]) -> None:
    op.create_table(
        name,
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("run_id", sa.Integer(), nullable=False),
        *extra,
        sa.ForeignKeyConstraint(["run_id"], ["runs.id"]),
        sa.PrimaryKeyConstraint("id"),
    )


def upgrade() -> None:
    with op.batch_alter_table("runs", schema=None) as batch_op:
        batch_op.add_column(sa.Column("robot_name", sa.String(length=100), nullable=False, server_default=""))
        batch_op.add_column(sa.Column("duration_s", sa.Float(), nullable=False, server_default="0"))
        batch_op.add_column(sa.Column("distance_m", sa.Float(), nullable=False, server_default="0"))
        batch_op.add_column(sa.Column("end_reason", sa.String(length=200), nullable=False, server_default=""))
    with op.batch_alter_table("run_events", schema=None) as batch_op:
        batch_op.create_index("ix_run_events_run_id_t", ["run_id", "t"], unique=False)

    _chunk_table(
        "run_sample_chunks",
        [
            sa.Column("t0", sa.Float(), nullable=False),
            sa.Column("t1", sa.Float(), nullable=False),
            sa.Column("n", sa.Integer(), nullable=False),
            sa.Column("labels", sa.JSON(), nullable=False),
            sa.Column("data", sa.LargeBinary(), nullable=False),
        ],
    )
    _chunk_table(
        "run_scan_chunks",
        [
            sa.Column("t0", sa.Float(), nullable=False),
            sa.Column("t1", sa.Float(), nullable=False),
            sa.Column("n", sa.Integer(), nullable=False),
            sa.Column("data", sa.LargeBinary(), nullable=False),
        ],
    )
    _chunk_table(
        "run_plans",
        [
            sa.Column("t", sa.Float(), nullable=False),
            sa.Column("n", sa.Integer(), nullable=False),
            sa.Column("length_m", sa.Float(), nullable=False),
            sa.Column("data", sa.LargeBinary(), nullable=False),
        ],
    )
    _chunk_table(
        "run_goals",
        [
            sa.Column("t", sa.Float(), nullable=False),
            sa.Column("t_end", sa.Float(), nullable=True),
            sa.Column("x", sa.Float(), nullable=False),
            sa.Column("y", sa.Float(), nullable=False),
            sa.Column("theta", sa.Float(), nullable=False),
            sa.Column("outcome", sa.String(length=50), nullable=False),
            sa.Column("reason", sa.String(), nullable=False),
        ],
    )
    _chunk_table(
        "run_grids",
        [
            sa.Column("t", sa.Float(), nullable=False),
            sa.Column("version", sa.Integer(), nullable=False),
            sa.Column("resolution", sa.Float(), nullable=False),
            sa.Column("origin_x", sa.Float(), nullable=False),
            sa.Column("origin_y", sa.Float(), nullable=False),
            sa.Column("origin_yaw", sa.Float(), nullable=False),
            sa.Column("width", sa.Integer(), nullable=False),
            sa.Column("height", sa.Integer(), nullable=False),
            sa.Column("data", sa.LargeBinary(), nullable=False),
        ],
    )
    # Seeks read the chunk whose t0 is the largest <= t: a (run_id, t0) index answers in one probe.
    for table, col in (
        ("run_sample_chunks", "t0"),
        ("run_scan_chunks", "t0"),
        ("run_plans", "t"),
        ("run_goals", "t"),
        ("run_grids", "t"),
    ):
        with op.batch_alter_table(table, schema=None) as batch_op:
            batch_op.create_index(f"ix_{table}_run_id", ["run_id"], unique=False)
            batch_op.create_index(f"ix_{table}_run_id_{col}", ["run_id", col], unique=False)


def downgrade() -> None:
    for table in ("run_grids", "run_goals", "run_plans", "run_scan_chunks", "run_sample_chunks"):
        op.drop_table(table)
    with op.batch_alter_table("run_events", schema=None) as batch_op:
        batch_op.drop_index("ix_run_events_run_id_t")
    with op.batch_alter_table("runs", schema=None) as batch_op:
        batch_op.drop_column("end_reason")
        batch_op.drop_column("distance_m")
        batch_op.drop_column("duration_s")
        batch_op.drop_column("robot_name")

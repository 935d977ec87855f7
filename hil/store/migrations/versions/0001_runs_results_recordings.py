"""Revision 1: runs, protocol outcomes, results, recordings.

Revision ID: 0001
Revises:
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None


def _run_fk() -> sa.Column[str]:
    return sa.Column("run_id", sa.String(64), sa.ForeignKey("runs.run_id", ondelete="CASCADE"),
                     primary_key=True)


def upgrade() -> None:
    op.create_table(
        "runs",
        sa.Column("run_id", sa.String(64), primary_key=True),
        sa.Column("certificate_id", sa.String(160), nullable=False, unique=True),
        sa.Column("serial", sa.String(64), nullable=False),
        sa.Column("unit_type", sa.String(200), nullable=False),
        sa.Column("axis", sa.String(40), nullable=False),
        sa.Column("station", sa.String(120), nullable=False),
        sa.Column("operator", sa.String(120), nullable=False),
        sa.Column("is_reference", sa.Boolean, nullable=False),
        sa.Column("attempt", sa.Integer, nullable=False),
        sa.Column("profile", sa.Text, nullable=False),
        sa.Column("profile_sha256", sa.String(64), nullable=False),
        sa.Column("software_version", sa.String(40), nullable=False),
        sa.Column("git_revision", sa.String(80)),
        sa.Column("drive_kind", sa.String(40), nullable=False),
        sa.Column("drive_model", sa.String(120)),
        sa.Column("firmware_version", sa.String(80)),
        sa.Column("started_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("ended_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("outcome", sa.String(16), nullable=False),
        sa.Column("aborted", sa.Boolean, nullable=False),
        sa.Column("certificate_path", sa.Text, nullable=False),
        sa.Column("certificate_sha256", sa.String(64), nullable=False),
        sa.Column("ingested_at", sa.DateTime(timezone=True), nullable=False),
    )
    op.create_index("ix_runs_serial_started", "runs", ["serial", "started_at"])
    op.create_index("ix_runs_started", "runs", ["started_at"])
    op.create_table(
        "protocol_outcomes",
        _run_fk(),
        sa.Column("protocol", sa.String(80), primary_key=True),
        sa.Column("outcome", sa.String(16), nullable=False),
        sa.Column("motion_time_s", sa.Float, nullable=False),
        sa.Column("wall_time_s", sa.Float, nullable=False),
        sa.Column("messages", sa.Text, nullable=False),
    )
    op.create_table(
        "results",
        _run_fk(),
        sa.Column("name", sa.String(120), primary_key=True),
        sa.Column("protocol", sa.String(80), nullable=False),
        sa.Column("value", sa.Float, nullable=False),
        sa.Column("unit", sa.String(40), nullable=False),
        sa.Column("standard_uncertainty", sa.Float, nullable=False),
        sa.Column("coverage_factor", sa.Float, nullable=False),
        sa.Column("expanded_uncertainty", sa.Float, nullable=False),
        sa.Column("degrees_of_freedom", sa.Float),
        sa.Column("nominal", sa.Float),
        sa.Column("lower_limit", sa.Float),
        sa.Column("upper_limit", sa.Float),
        sa.Column("marginal_fraction", sa.Float),
        sa.Column("outcome", sa.String(16), nullable=False),
    )
    op.create_index("ix_results_name", "results", ["name"])
    op.create_table(
        "recordings",
        _run_fk(),
        sa.Column("path", sa.String(400), primary_key=True),
        sa.Column("protocol", sa.String(80), nullable=False),
        sa.Column("excitation", sa.String(200), nullable=False),
        sa.Column("sha256", sa.String(64), nullable=False),
        sa.Column("samples", sa.Integer),
        sa.Column("complete", sa.Boolean, nullable=False),
    )


def downgrade() -> None:
    for table in ("recordings", "results", "protocol_outcomes", "runs"):
        op.drop_table(table)

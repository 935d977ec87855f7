"""Revision 4: gimbal certificates (part number, revision, one verdict over the axes' runs).

The runs stored before it keep their rows: a serial without a gimbal row is a one-axis
unit, as each of them was.

Revision ID: 0004
Revises: 0003
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "gimbals",
        sa.Column("certificate_id", sa.String(160), primary_key=True),
        sa.Column("serial", sa.String(64), nullable=False),
        sa.Column("part_number", sa.String(120), nullable=False),
        sa.Column("revision", sa.String(40), nullable=False),
        sa.Column("outcome", sa.String(16), nullable=False),
        sa.Column("issued_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("axes", sa.Text, nullable=False),
        sa.Column("certificate_path", sa.Text, nullable=False),
        sa.Column("certificate_sha256", sa.String(64), nullable=False),
        sa.Column("ingested_at", sa.DateTime(timezone=True), nullable=False),
    )
    op.create_index("ix_gimbals_serial_issued", "gimbals", ["serial", "issued_at"])


def downgrade() -> None:
    op.drop_index("ix_gimbals_serial_issued", table_name="gimbals")
    op.drop_table("gimbals")

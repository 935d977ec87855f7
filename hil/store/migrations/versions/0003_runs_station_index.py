"""Revision 3: an index for a station's runs over time (``results trend --station``, yields
per station).

Revision ID: 0003
Revises: 0002
"""

from __future__ import annotations

from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_index("ix_runs_station_started", "runs", ["station", "started_at"])


def downgrade() -> None:
    op.drop_index("ix_runs_station_started", table_name="runs")

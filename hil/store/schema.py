"""The results store's tables (SQLAlchemy Core), the same on SQLite and PostgreSQL.

One row per calibration run (keyed by a run id, unique by certificate id), with its
protocols' outcomes, its judged results and its raw recordings; and the frozen SPC
baselines. Times are stored in UTC. The migrations in ``migrations/versions`` build exactly
these tables; a test checks that the two agree.
"""

from __future__ import annotations

from sqlalchemy import (
    Boolean,
    Column,
    DateTime,
    Float,
    ForeignKey,
    Index,
    Integer,
    MetaData,
    String,
    Table,
    Text,
)

metadata = MetaData()

runs = Table(
    "runs",
    metadata,
    Column("run_id", String(64), primary_key=True),
    Column("certificate_id", String(160), nullable=False, unique=True),
    Column("serial", String(64), nullable=False),
    Column("unit_type", String(200), nullable=False),
    Column("axis", String(40), nullable=False),
    Column("station", String(120), nullable=False),
    Column("operator", String(120), nullable=False),
    Column("is_reference", Boolean, nullable=False),
    Column("attempt", Integer, nullable=False),
    Column("profile", Text, nullable=False),
    Column("profile_sha256", String(64), nullable=False),
    Column("software_version", String(40), nullable=False),
    Column("git_revision", String(80)),
    Column("drive_kind", String(40), nullable=False),
    Column("drive_model", String(120)),
    Column("firmware_version", String(80)),
    Column("started_at", DateTime(timezone=True), nullable=False),
    Column("ended_at", DateTime(timezone=True), nullable=False),
    Column("outcome", String(16), nullable=False),
    Column("aborted", Boolean, nullable=False),
    Column("certificate_path", Text, nullable=False),
    Column("certificate_sha256", String(64), nullable=False),
    Column("ingested_at", DateTime(timezone=True), nullable=False),
    Index("ix_runs_serial_started", "serial", "started_at"),
    Index("ix_runs_started", "started_at"),
    Index("ix_runs_station_started", "station", "started_at"),
)

protocol_outcomes = Table(
    "protocol_outcomes",
    metadata,
    Column("run_id", String(64), ForeignKey("runs.run_id", ondelete="CASCADE"),
           primary_key=True),
    Column("protocol", String(80), primary_key=True),
    Column("outcome", String(16), nullable=False),
    Column("motion_time_s", Float, nullable=False),
    Column("wall_time_s", Float, nullable=False),
    Column("messages", Text, nullable=False),  # JSON list of strings
)

results = Table(
    "results",
    metadata,
    Column("run_id", String(64), ForeignKey("runs.run_id", ondelete="CASCADE"),
           primary_key=True),
    Column("name", String(120), primary_key=True),
    Column("protocol", String(80), nullable=False),
    Column("value", Float, nullable=False),
    Column("unit", String(40), nullable=False),
    Column("standard_uncertainty", Float, nullable=False),
    Column("coverage_factor", Float, nullable=False),
    Column("expanded_uncertainty", Float, nullable=False),
    Column("degrees_of_freedom", Float),
    Column("nominal", Float),
    Column("lower_limit", Float),
    Column("upper_limit", Float),
    Column("marginal_fraction", Float),
    Column("outcome", String(16), nullable=False),
    Index("ix_results_name", "name"),
)

recordings = Table(
    "recordings",
    metadata,
    Column("run_id", String(64), ForeignKey("runs.run_id", ondelete="CASCADE"),
           primary_key=True),
    Column("path", String(400), primary_key=True),
    Column("protocol", String(80), nullable=False),
    Column("excitation", String(200), nullable=False),
    Column("sha256", String(64), nullable=False),
    Column("samples", Integer),
    Column("complete", Boolean, nullable=False),
)

spc_baselines = Table(
    "spc_baselines",
    metadata,
    Column("name", String(200), primary_key=True),
    Column("body", Text, nullable=False),  # JSON
    Column("frozen_at", DateTime(timezone=True), nullable=False),
)

# A gimbal certificate: the gimbal's identity and one verdict over its axes' runs (each a
# row of ``runs`` under the same serial). A serial with runs and no gimbal row is a
# one-axis unit: the runs stored before this table came are that, unchanged.
gimbals = Table(
    "gimbals",
    metadata,
    Column("certificate_id", String(160), primary_key=True),
    Column("serial", String(64), nullable=False),
    Column("part_number", String(120), nullable=False),
    Column("revision", String(40), nullable=False),
    Column("outcome", String(16), nullable=False),
    Column("issued_at", DateTime(timezone=True), nullable=False),
    Column("axes", Text, nullable=False),  # JSON: [{axis, certificate_id, outcome}]
    Column("certificate_path", Text, nullable=False),
    Column("certificate_sha256", String(64), nullable=False),
    Column("ingested_at", DateTime(timezone=True), nullable=False),
    Index("ix_gimbals_serial_issued", "serial", "issued_at"),
)

"""Alembic environment for the results store: always run programmatically by
:func:`hil.store.engine.open_store` on the connection it hands over (``config.attributes``)."""

from __future__ import annotations

from alembic import context

connection = context.config.attributes["connection"]
context.configure(connection=connection, target_metadata=None, render_as_batch=True)
with context.begin_transaction():
    if connection.dialect.name == "postgresql":
        # several stations opening one server at once: one migrates, the others wait
        connection.exec_driver_sql("SELECT pg_advisory_xact_lock(7243001)")
    context.run_migrations()

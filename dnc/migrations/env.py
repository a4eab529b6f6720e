"""Alembic environment: the engine comes from the caller (dnc.db.migrate), never from a URL
in an ini file, so tests, the CLI and the server all migrate exactly the database they use."""

from alembic import context

from dnc.models import Base

config = context.config
engine = config.attributes["engine"]

with engine.begin() as connection:
    context.configure(
        connection=connection,
        target_metadata=Base.metadata,
        render_as_batch=connection.dialect.name == "sqlite",
    )
    context.run_migrations()

"""Alembic environment of the logbook's revisions (``versions/``).

dischargelab runs the revisions itself (:func:`dischargelab.logbook.schema.prepare`), on
the connection it opened, inside the transaction that holds its lock, so this file only
hands that connection to Alembic: no ``alembic.ini`` and no URL are needed. A revision
never imports the package's current tables: it is a frozen step from one schema version
to the next.
"""

from alembic import context

connection = context.config.attributes.get("connection")
if connection is None:
    raise RuntimeError("the logbook's revisions run through dischargelab "
                       "(dischargelab.logbook.schema.prepare), on its connection")
context.configure(connection=connection,
                  target_metadata=context.config.attributes.get("metadata"),
                  render_as_batch=True)
with context.begin_transaction():
    context.run_migrations()

"""The command line, Prefect flows and all I/O.

A command runs its flow as a Prefect flow run only when a Prefect API is configured; otherwise
it calls the flow's function and Prefect is not imported (:mod:`flows.common.prefect_run`).
Where Prefect does start a temporary local API (a Dask backfill without a configured server,
the tests' Prefect test server), its defaults are set here, before Prefect is imported: no
analytics (the machine may be offline) and a start-up timeout long enough for a busy two-core
machine (the first start migrates a fresh SQLite database and takes ~15 s). Both can be
overridden from the environment.
"""

import os

os.environ.setdefault("PREFECT_SERVER_ANALYTICS_ENABLED", "false")
os.environ.setdefault("PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS", "180")

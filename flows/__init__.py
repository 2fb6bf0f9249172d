"""The command line, Prefect flows and all I/O.

Prefect runs here without a separate server: a flow started outside a server run brings up a
temporary local API in-process. Its defaults are set before Prefect is imported: no analytics
(the machine may be offline) and a start-up timeout long enough for a busy two-core machine
(the first start migrates a fresh SQLite database and takes ~15 s). Both can be overridden
from the environment.
"""

import os

os.environ.setdefault("PREFECT_SERVER_ANALYTICS_ENABLED", "false")
os.environ.setdefault("PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS", "180")

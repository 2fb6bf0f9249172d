"""Advisory file locks (``fcntl.flock``) that keep the writers of one warehouse apart."""

from __future__ import annotations

import fcntl
from contextlib import AbstractContextManager, contextmanager
from pathlib import Path
from typing import Iterator

from flows.common.errors import ValvemonError


@contextmanager
def file_lock(path: Path, busy: str | None = None) -> Iterator[None]:
    """An exclusive lock on ``path`` (created, with its folder) for the ``with`` block.

    Without ``busy`` it waits for the lock; with it, a lock someone else holds raises
    :class:`ValvemonError` with ``busy`` as the message.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    fh = open(path, "a+")
    try:
        if busy is None:
            fcntl.flock(fh, fcntl.LOCK_EX)
        else:
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                raise ValvemonError(busy) from None
        yield
    finally:
        fh.close()


def partition_lock(warehouse: Path, target: Path) -> AbstractContextManager:
    """Exclusive lock on one lake partition (``target``: a file in its ``date=`` folder) while it
    is read and rewritten: by the backfill's ingest units (read-merge-write) and by retention
    (``WAREHOUSE/.locks/lake/sensors/valve_id=…/date=….lock``)."""
    rel = target.parent.relative_to(Path(warehouse))
    return file_lock(Path(warehouse) / ".locks" / rel.parent / f"{rel.name}.lock")

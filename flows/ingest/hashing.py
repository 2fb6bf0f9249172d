"""The manifest's content hash of an export (BLAKE3; the SHA-256 of warehouses from before).

``flows.ingest.formats.open_export`` hashes every file of an export in :data:`HASH_BLOCK_BYTES`
blocks of a memory map, dropping each block's pages after it; :func:`legacy_hash` is computed
only for a file whose size matches a manifest row of an older warehouse (docs/ingest.md,
"Content hash")."""

from __future__ import annotations

import hashlib
import mmap
import os
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from blake3 import blake3


HASH_PREFIX = "blake3:"
"""The manifest's content hash is ``blake3:<64 hex digits>`` (BLAKE3-256 of the file's bytes)."""
LEGACY_HASH_PREFIX = "sha256:"
"""Files ingested before BLAKE3 keep their SHA-256, ``sha256:<64 hex digits>`` (docs/ingest.md)."""


HASH_BLOCK_BYTES = 16 * 1024 * 1024
""":func:`content_hash` hashes a memory map in blocks of this size and drops each block's pages
from the process after it (a plain memory map keeps every page of a large file resident until it
is unmapped)."""


def content_hash(paths: list[Path]) -> tuple[str, int]:
    """The manifest's content hash of an export's files, in order (``blake3:<hex>``), and their
    total size in bytes; the resident memory stays one block whatever the files' size."""
    hasher, total = blake3(), 0
    for p in paths:
        with open(p, "rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            total += size
            if not size:
                continue
            with mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as data, memoryview(data) as view:
                for a in range(0, size, HASH_BLOCK_BYTES):
                    hasher.update(view[a : a + HASH_BLOCK_BYTES])
                    data.madvise(mmap.MADV_DONTNEED, a, min(HASH_BLOCK_BYTES, size - a))
    return HASH_PREFIX + hasher.hexdigest(), total


def legacy_hash(path: Path) -> str:
    """The content hash the manifest held before BLAKE3: ``sha256:<hex>`` of the file's bytes."""
    with _mapped(path) as data:
        return LEGACY_HASH_PREFIX + hashlib.sha256(data).hexdigest()


@contextmanager
def _mapped(path: Path) -> Iterator[mmap.mmap | bytes]:
    """The file's bytes, memory-mapped (no copy; ``b""`` for an empty file)."""
    with open(path, "rb") as fh:
        if os.fstat(fh.fileno()).st_size == 0:
            yield b""
            return
        data = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
        try:
            yield data
        finally:
            data.close()

"""Streaming helpers the format modules share: a stream's bytes in blocks cut at line ends, and
an iterator's items with whether each is the last."""

from __future__ import annotations

from typing import IO, Iterator

WHOLE = 1 << 62
"""A batch or block size that means "the whole file in one"."""


def lookahead(it: Iterator) -> Iterator[tuple[object, bool]]:
    """Each item with whether it is the last."""
    prev = sentinel = object()
    for item in it:
        if prev is not sentinel:
            yield prev, False
        prev = item
    if prev is not sentinel:
        yield prev, True


def line_blocks(fh: IO[bytes], block_bytes: int) -> Iterator[bytes]:
    """The stream's bytes in blocks of about ``block_bytes`` that end at a line end (the last one
    where the stream ends); :data:`WHOLE`: one block."""
    size = -1 if block_bytes >= WHOLE else block_bytes
    rest = b""
    while True:
        chunk = fh.read(size)
        if not chunk:
            if rest:
                yield rest
            return
        data = rest + chunk if rest else chunk
        cut = data.rfind(b"\n") + 1
        if cut == 0:
            rest = data
            continue
        rest = data[cut:]
        yield data[:cut]

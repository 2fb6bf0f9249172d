"""flows/common/allocator.py: freed heap memory is reused without page faults (glibc)."""

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

_PROBE = textwrap.dedent("""
    import resource, sys
    import numpy as np
    from numpy._core.multiarray import _set_madvise_hugepage
    _set_madvise_hugepage(False)  # 4 KiB pages: one fault per page touched afresh
    if sys.argv[1] == "retain":
        from flows.common.allocator import retain_freed_memory
        assert retain_freed_memory()
    a = np.ones(8 << 20)  # 64 MiB, touched
    del a
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    b = np.ones(8 << 20)  # the same size again
    print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
""")


def _faults(mode: str) -> int:
    root = Path(__file__).parents[2]
    out = subprocess.run([sys.executable, "-c", _PROBE, mode], cwd=root, capture_output=True, text=True, check=True)
    return int(out.stdout.split()[-1])


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_freed_memory_is_reused_without_page_faults():
    # 64 MiB is 16,384 pages of 4 KiB: glibc maps such a block afresh each time, unless told to
    # keep it in the heap
    assert _faults("default") > 10_000
    assert _faults("retain") < 500

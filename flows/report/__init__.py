"""``valvemon report`` and ``valvemon query``: views, the read-only snapshot, pictures, HTML, BI export, the Eq. 9 standstill check."""

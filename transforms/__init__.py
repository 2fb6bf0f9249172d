"""Pure polars/numpy computations (no I/O, no Prefect).

Monitoring (Steinboeck et al. 2013, steps 2–5a), one module per concern:

* :mod:`transforms.params` — :class:`~transforms.params.MonitorParams` (design data + settings)
* :mod:`transforms.windows` — monitoring windows from time gaps
* :mod:`transforms.derivatives` — Savitzky–Golay values and derivatives
* :mod:`transforms.selection` — step 3: which samples may become points, and counts
* :mod:`transforms.points` — Eq. 7 and its siblings: opening-area points
* :mod:`transforms.characteristic` — the piecewise-linear Â(u)
* :mod:`transforms.baseline` — step 4a (fitting Â) and step 5a (plausibility)
* :mod:`transforms.fit` — step 4b, Eq. 8, batched
* :mod:`transforms.monitor` — steps 2–4b composed for lake frames

Other subpackages (``transforms.ingest``, ``transforms.discrepancy``) serve their own flows.
Nothing is imported here, so ``import transforms.<module>`` stays light.
"""

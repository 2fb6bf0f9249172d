"""``valvemon discrepancy``: the model-discrepancy workflow's I/O, Prefect flow and pictures."""

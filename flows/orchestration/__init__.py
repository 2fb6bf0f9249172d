"""Runs over spans and schedules: ``valvemon backfill``, ``valvemon serve`` (nightly), Dask task runners."""

"""``valvemon ingest``: historian exports into the sensor lake."""

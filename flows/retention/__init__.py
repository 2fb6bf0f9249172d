"""Raw-data retention: ``valvemon retention`` thins or drops old lake partitions once their fits exist."""

"""``valvemon simulate``: synthetic historian archives from the closed-loop simulator."""

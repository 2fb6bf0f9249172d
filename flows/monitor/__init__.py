"""``valvemon monitor``: sensor lake → opening-area points → α̂/x̂/e fits."""

"""Telling the plant what changed: the night's condition changes recorded, composed into one
message and sent by webhook and mail, reliably (``docs/notify.md``)."""

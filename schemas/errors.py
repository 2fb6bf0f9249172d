"""The error of an invalid plant configuration (import-light: the command line catches it)."""


class ConfigError(ValueError):
    """An invalid plant configuration; the message names the key and the problem."""

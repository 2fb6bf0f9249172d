"""Errors the command line reports as one line on stderr with a non-zero exit status."""


class ValvemonError(Exception):
    """A failure the user can act on; the message names the file, row, tag or key involved."""

"""One error type for bad input: the CLI prints its message on one line and exits non-zero."""


class GratNetError(Exception):
    """A user-facing error: bad input, unsupported file, impossible parameters.

    The message must say what is wrong and, where possible, what to do instead.
    """

    exit_code = 2

"""The one exception type users see: it carries a message that names the file, field or device and what to do."""


class WolfcalError(Exception):
    """A problem with the user's input or environment; the CLI prints it and exits with a non-zero code."""

    exit_code = 2

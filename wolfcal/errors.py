"""The one exception type users see: it carries a message that names the file, field or device and what to do.

Its `exit_code` is the command's exit status (docs/cli.md): 2 bad usage or input (also click's own usage errors),
1 a run that finished but whose verdict refuses the files to deploy, 3 the servo bus failed, 4 the camera failed;
0 done, 130 interrupted (Ctrl-C) come from the command line itself.
"""


class WolfcalError(Exception):
    """A problem with the user's input or environment; the CLI prints it and exits with a non-zero code."""

    exit_code = 2


class DeployRefused(WolfcalError):
    """The run finished and wrote its report, but its verdict refuses the files to deploy (the report says why)."""

    exit_code = 1

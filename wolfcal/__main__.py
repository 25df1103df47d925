"""`python -m wolfcal`: the same command line as `wolfcal`."""

from wolfcal.cli import app

app(prog_name="wolfcal")

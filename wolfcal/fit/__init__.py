"""`wolfcal fit`: the estimation problem, its solver and the result file."""

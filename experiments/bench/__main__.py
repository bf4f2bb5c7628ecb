"""`python -m experiments.bench ...`: the same as `rbp bench ...`."""

from experiments.bench import main

raise SystemExit(main(prog="python -m experiments.bench"))

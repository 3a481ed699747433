"""Dev tooling that is not the product: the throughput bench (`make bench`) and the start-up
soak (`make soak`). Run from the repository root with `PYTHONPATH=tests`."""

"""The benchmarks of `make bench` (`python -m benchmarks --out build/bench` from the repository root): one module per
benchmark, each with `run() -> dict`. They live beside the package, not in it, so `pip install darthand` does not
install them."""

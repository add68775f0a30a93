"""Benchmarks and studies of margin_rl (not installed with the package): ``speed/`` times the package, ``studies/``
measures its results, ``tools/`` checks the package itself; ``harness`` is the speed benchmarks' shared timing
and reporting. Every script runs from the repository root, e.g. ``python benchmarks/speed/bench_env.py --help``."""

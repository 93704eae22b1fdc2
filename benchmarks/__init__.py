"""Benchmarks: scripts that print speed figures (the kernel, the environment, training throughput).

Developer tools run from a checkout (``python -m benchmarks.bench_env``); not part of the installed package.
"""

"""jaxobs's benchmarks: throughput, gradient cost and memory beside numba and NumPy baselines.

Run from the repository root: ``make bench`` (the full run, results in
``benchmarks/results/<date>.json``) or ``python -m benchmarks [--quick] [--json] [--out FILE]``.
Not part of the installed library.

- :mod:`benchmarks.workloads`: the workloads as jaxobs runs them (every call into the jaxobs API);
- :mod:`benchmarks.kernels`: the same steps by hand, plain Python compiled by numba or run by NumPy;
- :mod:`benchmarks.baselines`: the kernels on the workloads' parameters and inputs;
- :mod:`benchmarks.run`: timing, result rows, the text table.
"""

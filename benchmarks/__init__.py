"""jaxobs's benchmarks: throughput, gradient cost and memory beside numba and NumPy baselines; time to result; scale.

Run from the repository root: ``make bench`` (the full run, results in
``benchmarks/results/<date>.json``) or ``python -m benchmarks [--quick] [--json] [--out FILE]
[--only PART ...] [--no-time-to-result] [--no-scale]`` (:mod:`benchmarks.__main__`).
Not part of the installed library.

- :mod:`benchmarks.workloads`: the workloads as jaxobs runs them (every call into the jaxobs API);
- :mod:`benchmarks.kernels`: the same steps by hand, plain Python compiled by numba or run by NumPy;
- :mod:`benchmarks.baselines`: the kernels on the workloads' parameters and inputs;
- :mod:`benchmarks.run`: timing, result rows, the text table;
- :mod:`benchmarks.extra`: the full run's time-to-result (:mod:`benchmarks.first_second`) and scale
  (:mod:`benchmarks.scale`) parts.
"""

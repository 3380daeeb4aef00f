"""Files in and out; no JAX.

- :mod:`jaxobs.io.files`: the one file writer (atomic: a temporary file renamed over the target);
- :mod:`jaxobs.io.provenance`: versions and sha256 on every result, ``read_file`` (the one input reader) and
  ``cf_dataset`` (every NetCDF made CF-1.8);
- :mod:`jaxobs.io.safetoml`: ``read_toml``, TOML read safely (size, encoding, nesting, number lengths).

The package itself imports nothing.
"""

"""Studies: designs × a family's scenarios → a labelled ``xarray.Dataset``.

- :mod:`jaxobs.studies.study`: the one study runner ``study``, its preset ``run_study``, ``write_study``;
- :mod:`jaxobs.studies.drive`: ``run_drive_study``, the drive family's preset;
- :mod:`jaxobs.studies.demo`: the FLL demo's table;
- :mod:`jaxobs.studies.registry`: observer names and aliases → classes, signals, machines (application facts).

The package itself imports nothing.
"""

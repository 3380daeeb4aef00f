"""Studies: designs × a family's scenarios → a labelled ``xarray.Dataset``.

- :mod:`jaxobs.studies.study`: the one study runner ``study``, its one preset ``run_study`` (each family declares its
  study), ``write_study``;
- :mod:`jaxobs.studies.drive`: the drive study's doc, and ``run_drive_study``, ``run_study``'s deprecated alias;
- :mod:`jaxobs.studies.demo`: the FLL demo's table;
- :mod:`jaxobs.studies.registry`: observer names and aliases → classes, signals, machines (application facts).

The package itself imports nothing.
"""

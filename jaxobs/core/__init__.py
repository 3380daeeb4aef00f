"""The foundations every other package stands on; no project imports.

- :mod:`jaxobs.core.numerics`: safe elementary functions (``wrap``, ``safe_atan2``, ``safe_norm2``);
- :mod:`jaxobs.core.trig`: ``sincos``, one sine and cosine per angle;
- :mod:`jaxobs.core.validate`: eager argument checks that raise a ``ValueError`` naming the field and its range;
- :mod:`jaxobs.core.sampletime`: ``SampleTime``, exact sample instants;
- :mod:`jaxobs.core.system`: ``AbstractSystem``, the contract :func:`jaxobs.simulate` runs;
- :mod:`jaxobs.core.measurements`: ``DriveInput``, what a drive observer is given each period;
- :mod:`jaxobs.core.discretize`: the integration rules (Euler, Tustin, AB3, RK4) and input paths;
- :mod:`jaxobs.core.quantities`: the records of the axis and metric tables (``Axis``, ``Metric``).

The package itself imports nothing, so that importing one foundation does not import the others.
"""

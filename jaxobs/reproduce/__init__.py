"""Paper reproductions run on the simulated drives (``jaxobs reproduce ...``)."""

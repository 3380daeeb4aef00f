"""Analyses of designs above the studies they run: the closed loop's stability verdict
(:mod:`jaxobs.analysis.stability`) and the operating envelope over speed × load
(:mod:`jaxobs.analysis.envelope`).  The package itself imports nothing: import its modules."""

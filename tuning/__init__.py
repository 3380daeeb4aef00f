"""Tuning jobs (objectives, gain parametrizations, optimizers, job files) — filled by the tuning issue."""

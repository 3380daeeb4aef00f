"""What a drive observer is given each control period (the lowest layer: signals, drive and observers use it).

Frame and units: stationary (αβ) frame, amplitude-invariant Clarke transform,
volts and amperes.  The voltage is the one applied over the period that
starts at the sample (what a DSP knows at t_k: it computed it at t_{k−1}).
"""

from __future__ import annotations

from typing import NamedTuple

import jax

__all__ = ["DriveInput"]


class DriveInput(NamedTuple):
    """Measured stationary-frame voltage and current at one sample (module doc).

    Attributes:
        u_a: u_α, the voltage applied over the period that starts at the sample, V.
        u_b: u_β, V.
        i_a: i_α at the sample, A.
        i_b: i_β at the sample, A.
    """

    u_a: jax.Array
    u_b: jax.Array
    i_a: jax.Array
    i_b: jax.Array

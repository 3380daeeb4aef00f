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
        T_ref: The torque reference the controller held over the period that ends at the sample, N·m, or None
            where there is none (a recording, a signal-level use): a mechanical-model speed observer
            (:class:`jaxobs.observers.speed.MechanicalSpeed`) then takes 0.  None, not 0.0, so that a batch of
            inputs without it still scans and vmaps (None is an empty PyTree).
    """

    u_a: jax.Array
    u_b: jax.Array
    i_a: jax.Array
    i_b: jax.Array
    T_ref: jax.Array | None = None

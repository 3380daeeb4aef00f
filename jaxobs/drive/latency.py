"""The DSP's timing: where the currents are sampled, when the voltage computed from them is applied, and at
which instant an estimate is compared with the encoder (:class:`Latency`, an option of
:class:`~jaxobs.drive.Drive`).

Time line of a digital drive with symmetric PWM of period T_s (one control period per PWM period; the
voltage of PWM period k is held over [t_k, t_{k+1}]):

- *sampling* (:class:`PeriodStart` or :class:`PWMCentre`): the ADC samples the currents, and the encoder is
  latched, at τ_k = t_k + σ T_s, σ = 0 (counter zero) or ½ (counter peak).  Both are the ripple-free
  instants of centre-aligned PWM, so the average-value plant gives the sample exactly;
- *computation delay* c ∈ {0, 1} periods: the ISR that starts at τ_k delivers its voltage at τ_k + c T_s
  (0: an ideal instantaneous controller; 1: the whole period, as the papers' DSPs at 10 kHz);
- *PWM update*: the new duty cycles load at the next period boundary (single update, shadow registers
  loaded at counter zero), so the voltage of ISR k drives PWM period k + D, D = ⌈σ + c⌉ periods after the
  period it was sampled in: D = 1 for start/1 (the default), 2 for centre/1, 1 for centre/0, 0 for start/0.
  It is applied from t_{k+D} for one period, centred (⌈σ + c⌉ + ½ − σ) T_s after its sample: the *use
  delay* n of :attr:`Latency.use_delay`, 1.5 samples by default, 2 samples for centre/1.

The FOC compensates n samples by rotating its output ahead by ``FOC.advance`` × ω̂e T_s (default 1.5: exact
for the default timing); 0 is no compensation.

The observer is told the voltage of the PWM period that holds the sample instant, where it is already
decided (D ≥ 1: the command the DSP issued earlier), else (start/0) that of the period just ended.

*Comparison* (:class:`AtSample`, :class:`AtUse`): an estimate made from the samples at τ_k is compared with
the rotor's angle at τ_k (its own time stamp, the default: the observer's error alone), or with the rotor's
angle when the voltage computed from it acts, τ_k + n T_s (the encoder's "now" while that estimate is in
use: the observer's error plus the latency, n ω_e T_s at steady speed).  The latter is what the papers'
oscilloscopes show, the D/A's θ̂ beside the encoder's θ; it is extrapolated from τ_k at the true speed
(at the 000 bench's 1000 rad/s² speed ramps the extrapolation is off by ½ (dω_e/dt)(n T_s)² = 2e-5 rad).
"""

from __future__ import annotations

import math

import equinox as eqx

__all__ = ["Latency", "PeriodStart", "PWMCentre", "AtSample", "AtUse"]


class PeriodStart(eqx.Module):
    """The currents are sampled at the start of the PWM period (counter zero), σ = 0."""

    offset = 0.0  # σ, periods after t_k


class PWMCentre(eqx.Module):
    """The currents are sampled at the centre of the PWM period (counter peak), σ = ½."""

    offset = 0.5


class AtSample(eqx.Module):
    """Compare an estimate with the rotor at its own time stamp (the sample instant): the observer's error."""

    def lead(self, latency: Latency) -> float:
        """How many periods after the sample instant the rotor's angle is taken.

        Args:
            latency: The drive's :class:`Latency`.

        Returns:
            The periods.
        """
        return 0.0


class AtUse(eqx.Module):
    """Compare an estimate with the rotor while the voltage computed from it acts (the encoder's now):
    the observer's error plus the latency, ≈ n ω_e T_s (n = :attr:`Latency.use_delay`)."""

    def lead(self, latency: Latency) -> float:
        """The lead of the comparison instant over the sample: the use delay.

        Args:
            latency: The drive's timing.

        Returns:
            The lead, periods.
        """
        return latency.use_delay


class Latency(eqx.Module):
    """The sampling, computation and PWM-update timing of the drive's DSP (module doc), and the instant at
    which its estimates are compared with the encoder.

    The default timing: sampling at the period start, one period of computation, estimates compared at their
    own time stamp.

    Args:
        sampling: :class:`PeriodStart` (default) or :class:`PWMCentre`.
        compute_delay: c, the computation's periods (0 or 1).
        compare: :class:`AtSample` (default) or :class:`AtUse`.

    Raises:
        ValueError: A value outside its choices, naming the field.
    """

    sampling: PeriodStart | PWMCentre = eqx.field(static=True)
    compute_delay: int = eqx.field(static=True)  # c, periods (0 or 1)
    compare: AtSample | AtUse = eqx.field(static=True)

    def __init__(self, sampling=None, compute_delay=1, compare=None):
        sampling = PeriodStart() if sampling is None else sampling
        if not isinstance(sampling, (PeriodStart, PWMCentre)):
            raise ValueError(f"Latency.sampling must be PeriodStart() or PWMCentre(), got {type(sampling).__name__}")
        if isinstance(compute_delay, bool) or compute_delay not in (0, 1):
            raise ValueError(f"Latency.compute_delay must be 0 or 1 (periods), got {compute_delay!r}")
        compare = AtSample() if compare is None else compare
        if not isinstance(compare, (AtSample, AtUse)):
            raise ValueError(f"Latency.compare must be AtSample() or AtUse(), got {type(compare).__name__}")
        self.sampling = sampling
        self.compute_delay = int(compute_delay)
        self.compare = compare

    @property
    def sample_offset(self) -> float:
        """σ: the sample instant after the period start, periods."""
        return self.sampling.offset

    @property
    def pipeline(self) -> int:
        """D: the PWM period that the voltage of ISR k drives is k + D."""
        return math.ceil(self.sample_offset + self.compute_delay)

    @property
    def use_delay(self) -> float:
        """n: from the sample instant to the centre of the PWM period its voltage drives, periods."""
        return self.pipeline + 0.5 - self.sample_offset

    @property
    def compare_lead(self) -> float:
        """Periods after the sample instant at which the rotor's angle is compared with the estimates."""
        return self.compare.lead(self)

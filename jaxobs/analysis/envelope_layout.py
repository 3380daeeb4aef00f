"""The envelope's dataset: its per-point variables (:data:`ENVELOPE_VARIABLES`, units and long names) and the
labelled ``xarray.Dataset`` :func:`jaxobs.analysis.envelope.envelope` returns (:func:`envelope_dataset`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from ..drive import Drive, DualDrive, DualPMSMParams, PMSMParams
from ..io.provenance import cf_dataset, provenance
from ..scenarios.families import DRIVE_STUDY_AXES
from ..studies.study import gain_variables

if TYPE_CHECKING:
    import xarray as xr

__all__ = ["ENVELOPE_VARIABLES", "REVERSAL_VARIABLES", "envelope_dataset", "reversal_variables"]

# variable -> (units, long_name) of the per-point results
ENVELOPE_VARIABLES = {
    "margin": (
        "s-1",
        "stability margin: minus the largest non-neutral exponent of the sampled loop (log|Floquet multiplier|/period)",
    ),
    "stable": (
        "1",
        "stable: resolved stable in the small signal (linear_stable) and the long run neither lost speed nor lock "
        "nor diverged (run_state holds or bounded limit cycle) (1: stable)",
    ),
    "marginal": (
        "1",
        "marginal: |margin| within its resolution, the orbit held its speed: neither verdict (1: marginal)",
    ),
    "resolution": (
        "s-1",
        "resolution of the margin: how far the orbit was from periodic (floquet), or the exponent's spread over "
        "the window's thirds (lyapunov); NaN off the orbit (off_orbit: the rate is a bound, rate_bound)",
    ),
    "orbit_speed_dev": ("1", "max |speed - reference| / |reference| during the linearized run after its settle"),
    "off_orbit": (
        "1",
        "off orbit: the linearized run left its operating point (orbit_speed_dev >= 0.1): unstable, its rate a "
        "bound (1: off)",
    ),
    "rate_bound": (
        "s-1",
        "off the orbit: a lower bound on the growth rate, max(exponent - resolution, 0), measured along the "
        "departed trajectory; NaN on the orbit",
    ),
    "synchronous": (
        "1",
        "held synchronism over the long run after a speed-reference pulse: finite, locked, at speed, settled (1: held)",
    ),
    "lost_lock": ("1", "lost lock over the late window: diverged or position error > 90 deg electrical (1: lost)"),
    "lost_speed": ("1", "lost speed over the late window: diverged, or mean |speed - ref| > 20 % of |ref| (1: lost)"),
    "peak_position_late": ("rad", "peak |position error| in the late window (electrical)"),
    "mean_position_late": ("rad", "mean position error in the late window (electrical, signed): the steady bias"),
    "ripple_position_late": ("rad", "rms of the position error about its mean in the late window (electrical)"),
    "peak_speed_deviation_early": ("1", "peak |speed - reference| / |reference| in the early window"),
    "peak_speed_deviation_late": ("1", "peak |speed - reference| / |reference| in the late window"),
    "holds": ("1", "holds: stable, synchronous and peak position error within bound_deg (1: holds)"),
    "pulse": (
        "1",
        "the speed-reference pulse whose long run the point's run quantities are: +1 up, -1 down (each point runs "
        "both; the worse run: the higher run_state, then not synchronous; up on a tie)",
    ),
    "peak_position_event": ("rad", "peak |position error| from the pulse on (electrical): the verdict's lock test"),
    "mean_speed_error_late": ("rad s-1", "mean |speed - reference| in the late window (mechanical)"),
    "mean_speed_reference_late": ("rad s-1", "mean |reference| in the late window (mechanical)"),
    "speed_swing_first": ("rad s-1", "half peak-to-peak of speed - reference in the late window's first half"),
    "speed_swing_second": ("rad s-1", "half peak-to-peak of speed - reference in the late window's second half"),
    "run_finite": ("1", "every value of the long run stayed finite (1: finite)"),
    "run_state": (
        "1",
        "the long run's verdict alone (jaxobs.analysis.verdict.verdict_from on its windows): 0 holds, 1 bounded "
        "limit cycle, 2 loses speed, 3 loses lock, 4 unstable",
    ),
    "linear_stable": (
        "1",
        "the small-signal verdict alone: margin - resolution > 0 and the orbit held its speed (1: resolved stable)",
    ),
    "state": (
        "1",
        "the point's verdict: the long run's (run_state), but unstable where the run holds and the small-signal "
        "verdict is resolved unstable or off its orbit: 0 holds, 1 bounded limit cycle, 2 loses speed, 3 loses "
        "lock, 4 unstable",
    ),
}

# variable -> (units, long_name) of the reversal verdict (envelope's ``reversal=``), dims (design, reversal_load_nm)
REVERSAL_VARIABLES = {
    "reversal_rate": (
        "min-1 s-1",
        "slowest held reversal: the ramp rate (r/min per second) of the slowest probed +n to -n reversal from which "
        "every faster probed one holds; NaN: none held",
    ),
    "reversal_fails_at": (
        "min-1 s-1",
        "the nearest probed rate below reversal_rate that does not hold; NaN: every probed rate held "
        "(reversal_rate is then the range's slow end, a bound)",
    ),
    "reversal_resolution": ("1", "the bracket's relative width, reversal_rate / reversal_fails_at - 1"),
    "reversal_monotone": ("1", "the probes changed verdict once at most over the range (1: monotone)"),
    "reversal_probes": ("1", "batched simulations the search ran"),
    "reversal_probed": ("1", "every probed rate (r/min per second) and its verdict, rate:state, in probe order"),
}

# the verdict codes' CF flag attributes (jaxobs.analysis.verdict.VERDICTS, in code order)
STATE_VARIABLES = ("run_state", "state")
STATE_FLAGS = "holds bounded_limit_cycle loses_speed loses_lock unstable"


def envelope_dataset(
    res: Mapping[str, np.ndarray],
    designs: Mapping[str, Any],
    axes: Mapping[str, np.ndarray],
    names: Sequence[str],
    attrs: Mapping[str, Any],
    machine: PMSMParams,
    drive: Drive | DualDrive,
    dual: DualPMSMParams | None = None,
) -> xr.Dataset:
    """The envelope's CF dataset.

    Args:
        res: every variable of :data:`ENVELOPE_VARIABLES`, shaped (design, speed, load[, mismatch]).
        designs: name -> observer, in the order of the design dim (their gains: :func:`gain_variables`).
        axes: the axes' values, by name (speed_rpm, load_nm and the optional mismatch axis).
        names: the axes' names in the order of the dims after ``design``.
        attrs: the run's attributes (horizon, windows, the stability options).
        machine: the machine whose parameters are written as ``machine_`` attributes.
        drive: the drive that ran (its sample time and settle written as attributes).
        dual: the dual machine a :class:`~jaxobs.drive.DualDrive` ran, else None.

    Returns:
        The dataset, with the units and long names of :data:`ENVELOPE_VARIABLES` and provenance.
    """
    import xarray as xr

    dims = ("design", "speed_rpm", "load_nm", *names[2:])
    coords = {
        "design": ("design", list(designs), {"long_name": "observer design (closing the loop sensorless)"}),
        "speed_rpm": ("speed_rpm", axes["speed_rpm"], DRIVE_STUDY_AXES["speed_rpm"].attrs),
        "load_nm": ("load_nm", axes["load_nm"], DRIVE_STUDY_AXES["load_nm"].attrs),
    }
    for name in names[2:]:
        coords[name] = (name, axes[name], DRIVE_STUDY_AXES[name].attrs)
    data = {}
    for k, (unit, long_name) in ENVELOPE_VARIABLES.items():
        v = res[k]
        v = v.astype(np.int8) if v.dtype == bool or k in STATE_VARIABLES else v.astype(float)
        var_attrs: dict[str, object] = {"units": unit, "long_name": long_name}
        if k in STATE_VARIABLES:
            var_attrs.update(flag_values=np.arange(5, dtype=np.int8), flag_meanings=STATE_FLAGS)
        data[k] = (dims, v, var_attrs)
    data.update(gain_variables(dict(designs)))  # as the drive studies write them
    ds = xr.Dataset(data, coords=coords)
    ds.attrs.update(attrs)
    for f in ("Rs", "Ld", "Lq", "psi_f", "p", "J", "T_rated", "n_rated"):
        ds.attrs[f"machine_{f}"] = float(getattr(machine, f))
    ds.attrs.update(drive_ts=float(drive.ts), drive_settle=float(drive.settle))
    if dual is not None:  # the machine_ attributes are then the αβ subspace's, with the whole machine's J and ratings
        assert isinstance(drive, DualDrive)
        ds.attrs.update(machine_Lls=float(dual.Lls), drive_mode=drive.mode, drive_fw_voltage=drive.ctrl.fw_voltage)
    ds.attrs.update(provenance("jaxobs.analysis.envelope.envelope"))
    return cf_dataset(ds, "jaxobs operating envelope: where each design holds over speed x load")


def reversal_variables(rev: Mapping[str, np.ndarray], dnames: Sequence[str], opts: Mapping[str, Any]) -> dict[str, Any]:
    """The reversal verdict as dataset variables (:data:`REVERSAL_VARIABLES`) over ``("design",
    "reversal_load_nm")``, for ``Dataset.assign``.

    Args:
        rev: :func:`jaxobs.analysis.envelope_reversal.reversals`'s arrays, shaped (design, load).
        dnames: The designs, in the dataset's order.
        opts: The reversal's options (its ``loads_nm`` the new coordinate).

    Returns:
        name -> ``xarray.DataArray``, the coordinate ``reversal_load_nm`` included.
    """
    import xarray as xr

    dims = ("design", "reversal_load_nm")
    load_attrs = {"units": "N m", "long_name": "constant load torque of the reversal verdict's runs"}
    loads = np.asarray(opts["loads_nm"], dtype=float)
    coords = {"design": list(dnames), "reversal_load_nm": ("reversal_load_nm", loads, load_attrs)}
    src = {
        "reversal_rate": rev["rate"].astype(float),
        "reversal_fails_at": rev["other"].astype(float),
        "reversal_resolution": rev["resolution"].astype(float),
        "reversal_monotone": rev["monotone"].astype(np.int8),
        "reversal_probes": rev["probes"].astype(np.int32),
        "reversal_probed": rev["states"].astype(str),
    }
    out = {}
    for k, (unit, long_name) in REVERSAL_VARIABLES.items():
        attrs = {"long_name": long_name} if k == "reversal_probed" else {"units": unit, "long_name": long_name}
        out[k] = xr.DataArray(src[k], dims=dims, coords=coords, attrs=attrs)
    return out

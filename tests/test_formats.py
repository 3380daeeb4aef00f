"""Results in the field's formats: drive batch results as an xarray Dataset with the grid's dims."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxobs
from jaxobs import drive as D


def test_drive_batch_results_as_a_dataset_with_the_grid_dims():
    par = D.spmsm_paper000(inertia="motor")
    drv = D.Drive(D.FOC.imc(par, alpha_c=2 * jnp.pi * 300, alpha_s=2 * jnp.pi * 20))
    batch = D.grid(D.Scenario(par, load=D.Profile.constant(5.0)), speed_rpm=[500.0, 1000.0], dRs=[0.0, 0.5, 0.25])
    sols = jax.vmap(lambda s: jaxobs.simulate(D.ClosedLoop(drv, None, s), 0.01))(batch.scenarios)
    ds = batch.to_xarray(sols.outputs)
    assert ds["omega_m"].dims == ("speed_rpm", "dRs", "time") and ds.sizes["time"] == 100
    assert list(ds["dRs"].values) == [0.0, 0.5, 0.25]  # the grid's own order, not sorted
    assert ds["speed_rpm"].attrs["units"] == "min-1" and ds["omega_m"].attrs["units"] == "rad s-1"
    assert ds["time"].attrs["units"] == "s" and "t" not in ds and "obs" not in ds  # None: the encoder
    # each cell is its scenario's own trace (row-major over the dims, last axis fastest)
    flat = np.asarray(sols.outputs.omega_m)
    assert np.array_equal(ds["omega_m"].sel(speed_rpm=1000.0, dRs=0.25).values, flat[5])
    assert np.array_equal(ds["omega_m"].sel(speed_rpm=500.0, dRs=0.5).values, flat[1])
    per = batch.to_xarray({"rms": jnp.arange(6.0)})
    assert per["rms"].dims == ("speed_rpm", "dRs") and float(per["rms"].sel(speed_rpm=1000.0, dRs=0.0)) == 3.0
    with pytest.raises(ValueError, match="leading axis must be the batch"):
        batch.to_xarray({"rms": jnp.arange(5.0)})

"""Robustness studies: labelled results checked against single runs, NetCDF round trip, 10,000+ scenarios."""

import hashlib
import json
import math
import time
from importlib import resources
from pathlib import Path

import jax
import numpy as np
import pytest
import xarray as xr

import jaxobs
from jaxobs import linear, papers
from jaxobs import metrics as M
from jaxobs.io.provenance import by_label
from jaxobs.studies.study import run_study, worst_cases
from jaxobs_tuning.cli import main
from jaxobs_tuning.summary import study_warnings
from tests.cfcheck import assert_cf18

AXES = {"freq_step": [-2.0, 1.0], "dc": [0.0, 0.1], "phase_jump_deg": [0.0, 30.0]}


@pytest.fixture(scope="module")
def small_study():
    designs = {"SOGI-FLL": linear.sogi_fll_closed_form(), "WIF": linear.wif_closed_form()}
    return designs, run_study(designs, AXES, progress=False)


def test_dims_coords_and_values_match_single_runs(small_study):
    designs, ds = small_study
    assert ds["ripple_freq"].dims == ("design", "freq_step", "dc", "phase_jump_deg")
    assert list(ds["design"].values) == ["SOGI-FLL", "WIF"]
    np.testing.assert_array_equal(ds["dc"].values, [0.0, 0.1])
    t_event, steady = ds.attrs["t_event"], ds.attrs["steady_from"]
    for dname, fs, dc, pj in (("SOGI-FLL", -2.0, 0.1, 30.0), ("WIF", 1.0, 0.0, 0.0), ("WIF", -2.0, 0.1, 0.0)):
        sig = jaxobs.GridSignal(t_event=t_event, freq_step=fs, dc=dc, phase_jump=math.radians(pj))
        sol = jaxobs.simulate(jaxobs.OnSignal(designs[dname], sig), ds.attrs["horizon"])
        out = sol.outputs
        ferr = (out.obs.omega - out.truth.omega) / (2 * math.pi)
        ripple = float(M.peak_to_peak(ferr, sol.t >= steady))
        rms = float(M.rms(M.wrap(out.obs.theta - out.truth.theta), sol.t >= steady))
        cell = ds.sel(design=dname, freq_step=fs, dc=dc, phase_jump_deg=pj)
        assert float(cell["ripple_freq"]) == pytest.approx(ripple, rel=1e-9, abs=1e-12)
        assert float(cell["rms_phase_steady"]) == pytest.approx(rms, rel=1e-9, abs=1e-12)
    assert int(ds["diverged"].sum()) == 0 and int(ds["lost_lock"].sum()) == 0  # the closed forms hold lock
    # the SOGI-FLL's dc ripple is the worst case of the study
    worst = worst_cases(ds, "ripple_freq", 1)
    assert worst[0]["design"] == "SOGI-FLL" and worst[0]["dc"] == 0.1


def test_netcdf_round_trip(small_study, tmp_path):
    _, ds = small_study
    ds.to_netcdf(tmp_path / "s.nc", engine="h5netcdf")
    back = by_label(xr.load_dataset(tmp_path / "s.nc", engine="h5netcdf"))
    assert back.identical(ds)


def test_bad_study_arguments():
    with pytest.raises(ValueError, match="axis 'spin'"):
        run_study({"a": linear.wif_closed_form()}, {"spin": [1.0]})
    with pytest.raises(ValueError, match="horizon"):
        run_study({"a": linear.wif_closed_form()}, {"dc": [0.0]}, t_event=0.5, horizon=0.4)


def test_dataset_has_units_gains_settled_and_provenance(small_study, tmp_path):
    """Every variable and coordinate has CF units and a long name; the gains are numbers; the settling times
    censored at the horizon are flagged; two identical studies write byte-identical files."""
    designs, ds = small_study
    for name in [*ds.data_vars, *ds.coords]:
        if name == "design":  # a label, no quantity
            assert "long_name" in ds[name].attrs, name
            continue
        assert {"units", "long_name"} <= set(ds[name].attrs), name
        assert "see" not in ds[name].attrs["units"], name  # a CF unit, not a pointer elsewhere
    assert ds["rms_phase_steady"].attrs["units"] == "rad" and ds["freq_step"].attrs["units"] == "Hz"
    # each gain its own variable with its own units (CF)
    assert ds["gain_k"].dims == ("design",) and ds["gain_k"].attrs["units"] == "1"
    assert ds["gain_lam"].attrs["units"] == "rad2 s-2"
    assert float(ds["gain_k"].sel(design="SOGI-FLL")) == pytest.approx(float(designs["SOGI-FLL"].k))
    assert float(ds["gain_lam"].sel(design="WIF")) == pytest.approx(float(designs["WIF"].lam))
    assert np.isnan(float(ds["gain_k1"].sel(design="SOGI-FLL")))
    assert not any(isinstance(v, str) and "=" in v for v in ds.attrs.values())  # no gains as strings
    assert ds["settled"].dtype == bool and ds["settled"].dims == ds["settling_freq"].dims
    censored = np.isclose(ds["settling_freq"], ds.attrs["horizon"] - ds.attrs["t_event"], atol=2e-4)
    assert not np.any(censored & ds["settled"])  # a settling time at the horizon is never "settled"
    assert "seconds" not in ds.attrs and ds.attrs["jax_version"] == jax.__version__
    again, seconds = run_study(designs, AXES, progress=False, return_seconds=True)
    assert seconds > 0
    ds.to_netcdf(tmp_path / "a.nc", engine="h5netcdf")
    again.to_netcdf(tmp_path / "b.nc", engine="h5netcdf")
    assert (tmp_path / "a.nc").read_bytes() == (tmp_path / "b.nc").read_bytes()


def test_unsettled_runs_are_flagged():
    """A sluggish design on a short horizon has not settled: ``settled`` False, its time censored."""
    slow = jaxobs.SOGIFLL(k=0.3, lam=500.0)
    ds = run_study({"slow": slow}, {"freq_step": [3.0]}, horizon=0.2, progress=False)
    assert not bool(ds["settled"].squeeze())
    assert float(ds["settling_freq"].squeeze()) == pytest.approx(0.1, abs=2e-4)  # t[-1] - t_event


@pytest.mark.slow  # a scale run (~15 s of simulation, not compile), over the fast suite's budget; CI runs it
def test_study_of_more_than_10000_scenarios(tmp_path, capsys):
    """10,240 scenarios (random draws over 5 axes) of the SOGI-FLL-WIF in chunks of 2048; time reported."""
    t0 = time.time()
    ds = run_study(
        {"WIF": linear.wif_closed_form()},
        {
            "freq_step": [-3.0, 3.0],
            "phase_jump_deg": [-60.0, 60.0],
            "dc": [0.0, 0.1],
            "harmonics_scale": [0.0, 2.0],
            "noise": [0.0, 0.01],
        },
        sample=10240,
        horizon=0.3,
        chunk_size=2048,
        progress=False,
    )
    elapsed = time.time() - t0
    assert ds.sizes["sample"] == 10240 and int(ds["diverged"].sum()) == 0
    assert np.all(np.isfinite(ds["rms_phase_steady"].values))
    print(f"\n10,240-scenario study: {elapsed:.1f} s on this machine")


def test_study_cli_default(tmp_path, capsys):
    assert main(["study", "--out", str(tmp_path), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "3 designs x 200 scenarios" in out
    # the table labels its units (the phase in degrees, as the figures)
    assert "settling_freq (s) mean" in out and "ripple_freq (Hz) mean" in out and "rms_phase_steady (deg) mean" in out
    assert_cf18(tmp_path / "study.nc")  # CF 1.8: compliance-checker, attributes, types
    ds = by_label(xr.load_dataset(tmp_path / "study.nc", engine="h5netcdf"))
    assert set(ds["design"].values) == {"SOGI-FLL", "SOGI-FLL-WPF", "SOGI-FLL-WIF"}
    worst = json.loads((tmp_path / "worst_cases.json").read_text())
    assert worst["ripple_freq"][0]["design"] == "SOGI-FLL"
    assert len(list(tmp_path.glob("heatmap_*.png"))) == 3
    # provenance: the study file's sha256 (here the packaged default study)
    default = Path(str(resources.files("jaxobs") / "data" / "default_study.toml"))
    assert ds.attrs["study_sha256"] == hashlib.sha256(default.read_bytes()).hexdigest()


def test_study_file_errors(tmp_path, capsys):
    p = tmp_path / "s.toml"
    p.write_text('[designs.a]\nclosed_form = "nope"\n[axes]\ndc = [0.0]\n')
    assert main(["study", str(p)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "designs.a.closed_form" in err[0]
    # a closed form is named by its short name or by its class's name, alike
    from jaxobs_tuning.study_file import load_study

    for name in ("wif", "SOGIFLLWIF"):
        p.write_text(f'[designs.a]\nclosed_form = "{name}"\n[axes]\nfreq_step = [1.0]\n')
        assert type(load_study(p).designs["a"]).__name__ == "SOGIFLLWIF"


def test_grid_signals_check_values_like_gridsignal_and_match_it():
    from jaxobs.scenarios import grid_signals

    with pytest.raises(ValueError, match="axis sag"):
        grid_signals(["sag"], [(1.5,)], 0.1, 50.0)
    with pytest.raises(ValueError, match="axis freq_step"):
        grid_signals(["freq_step"], [(-60.0,)], 0.1, 50.0)
    with pytest.raises(ValueError, match="axis noise"):
        grid_signals(["noise"], [(-0.1,)], 0.1, 50.0)
    # the vectorized batch equals signals built one by one
    sigs = grid_signals(
        ["freq_step", "phase_jump_deg", "harmonics_scale"], [(2.0, 30.0, 1.0), (-1.0, 0.0, 0.5)], 0.1, 50.0
    )
    t = np.linspace(0.0, 0.3, 301)
    harmonics = {h: 0.5 * m for h, m in papers.TEST_C_HARMONICS.items()}
    one = jaxobs.GridSignal(t_event=0.1, freq_step=-1.0, harmonics=harmonics)
    second = jax.tree.map(lambda x: x[1], sigs)
    np.testing.assert_array_equal(np.asarray(second(t)), np.asarray(one(t)))


def test_noise_axis_is_white_in_time_and_driven_by_the_seed():
    """The noise an observer sees on a noisy grid signal: a new draw every sample (not a constant offset),
    std as asked, the same draw for the same sample index, and another one for another seed."""
    from jaxobs.scenarios import grid_signals

    obs = jaxobs.linear.sogi_fll_closed_form()

    def seen(seed):
        sig = jax.tree.map(lambda x: x[0], grid_signals(["noise"], [(0.1,)], 0.1, 50.0, seed=seed))
        sol = jaxobs.simulate(jaxobs.OnSignal(obs, sig), 0.2)
        return np.asarray(sol.outputs.u) - np.asarray(sig.clean(sol.t))

    a, b = seen(0), seen(1)
    assert abs(np.std(a) - 0.1) < 0.01 and abs(np.mean(a)) < 0.01
    assert abs(np.corrcoef(a[1:], a[:-1])[0, 1]) < 0.1  # white: no sample-to-sample correlation
    np.testing.assert_array_equal(a, seen(0))
    assert not np.allclose(a, b)


def test_lost_lock_and_diverged_scenarios_are_flagged_and_listed_first():
    """A false lock (k = 20, λ = 1e4: finite, 115 rad/s against 326.7) is flagged lost_lock but not diverged;
    a NaN gain diverges (lost_lock too); the closed form holds lock.  worst_cases lists the diverged first."""
    import equinox as eqx
    import jax.numpy as jnp

    good = linear.sogi_fll_closed_form()
    designs = {
        "closed form": good,
        # the constructor would refuse these; set as arrays of the closed form's own dtype (a Python float
        # would be a static field: one more compilation per design)
        "false lock": eqx.tree_at(
            lambda o: (o.k, o.lam), good, (jnp.full_like(good.k, 20.0), jnp.full_like(good.lam, 1e4))
        ),
        "nan": eqx.tree_at(lambda o: o.lam, good, jnp.full_like(good.lam, float("nan"))),
    }
    ds = run_study(designs, {"freq_step": [-1.0, 2.0]}, progress=False)
    assert ds["lost_lock"].dtype == np.int8 and ds["lost_lock"].dims == ("design", "freq_step")
    assert list(ds["lost_lock_count"].values) == [0, 2, 2]
    assert list(ds["diverged"].sum("freq_step").values) == [0, 0, 2]
    assert np.all(np.isfinite(ds["rms_phase_steady"].sel(design="false lock")))  # finite, yet far from the truth
    worst = worst_cases(ds, "rms_phase_steady", 2)
    assert [(w["design"], w["diverged"], w["lost_lock"]) for w in worst] == [
        ("closed form", False, False),
        ("closed form", False, False),
        ("false lock", False, True),
        ("false lock", False, True),
        ("nan", True, True),
        ("nan", True, True),
    ]
    assert worst[-1]["value"] is None and json.loads(json.dumps(worst, allow_nan=False)) == worst
    # what `jaxobs study` prints on stderr after its table: the designs that lost anything, nothing of the others
    assert study_warnings(ds) == [
        "false lock: diverged in 0, lost lock in 2 of 2 scenarios",
        "nan: diverged in 2, lost lock in 2 of 2 scenarios",
    ]


def test_study_warnings_on_stderr_name_what_each_design_lost(tmp_path, capsys):
    """Noise of 10 p.u. makes both designs lose lock in that scenario; the warnings
    go to stderr (one line a design, after the table), stdout keeps the table alone."""
    study = tmp_path / "w.toml"
    study.write_text(
        '[study]\nname = "w"\nt_event = 0.02\nhorizon = 0.05\n[designs.SOGI-FLL]\nclosed_form = "sogi-fll"\n'
        '[designs.WIF]\nclosed_form = "wif"\n[axes]\nfreq_step = [1.0]\nnoise = [0.0, 10.0]\n'
    )
    assert main(["study", str(study), "--out", str(tmp_path / "o"), "--quiet"]) == 0
    got = capsys.readouterr()
    assert got.err.splitlines() == [
        "jaxobs: warning: SOGI-FLL: diverged in 0, lost lock in 1 of 2 scenarios",
        "jaxobs: warning: WIF: diverged in 0, lost lock in 1 of 2 scenarios",
    ]
    assert "jaxobs: warning" not in got.out
    rows = [line.split() for line in got.out.splitlines() if line.startswith(("SOGI-FLL", "WIF"))]
    assert [r[-2:] for r in rows] == [["0", "1"], ["0", "1"]]  # the table's diverged and lost lock columns


def test_worst_cases_put_diverged_scenarios_first():
    """Diverged scenarios (NaN metric) come first, flagged, value None; then the finite values, largest first."""
    vals = np.array([[0.3, np.nan, 0.9, 0.1]])
    ds = xr.Dataset(
        {
            "m": (("design", "dc"), vals),
            "diverged": (("design", "dc"), np.isnan(vals).astype(np.int8)),
            "lost_lock": (("design", "dc"), np.array([[0, 1, 1, 0]], np.int8)),
        },
        coords={"design": ["a"], "dc": [0.0, 0.1, 0.2, 0.3]},
    )
    w = worst_cases(ds, "m", 3)
    assert [(r["dc"], r["value"], r["diverged"], r["lost_lock"]) for r in w] == [
        (0.1, None, True, True),
        (0.2, 0.9, False, True),
        (0.0, 0.3, False, False),
    ]
    assert len(worst_cases(ds, "m", 10)) == 4  # nothing dropped


def test_samplers_points_and_layouts():
    """Grid: the Cartesian product, row-major; Random: numpy's uniform draws in axis order; Sobol and LHS:
    scipy.stats.qmc scaled into [min, max] (an axis of one value stays at it); a sample's layout is one
    ``sample`` dim with the axes as coordinates."""
    from scipy.stats import qmc

    from jaxobs.scenarios import LHS, Grid, Random, Sobol

    axes = {"dc": [0.0, 0.1], "sag": [0.2, 0.5, 0.3]}
    g = Grid(axes)
    assert g.points()[:4] == [(0.0, 0.2), (0.0, 0.5), (0.0, 0.3), (0.1, 0.2)] and len(g.points()) == 6
    dims, shape, coords = g.layout(lambda n: {"units": "1"})
    assert dims == ("dc", "sag") and shape == (2, 3) and list(coords["sag"][1]) == [0.2, 0.5, 0.3]
    rng = np.random.default_rng(7)
    want = [(rng.uniform(0.0, 0.1), rng.uniform(0.2, 0.5)) for _ in range(3)]
    assert Random(axes, 3, 7).points() == want
    u = qmc.Sobol(2, scramble=True, seed=3).random(4)
    np.testing.assert_array_equal(np.asarray(Sobol(axes, 4, 3).points()), qmc.scale(u, [0.0, 0.2], [0.1, 0.5]))
    pts = np.asarray(LHS({"dc": [0.05], "sag": [0.2, 0.5]}, 5, 1).points())
    assert np.all(pts[:, 0] == 0.05) and np.all((pts[:, 1] >= 0.2) & (pts[:, 1] <= 0.5))
    dims, shape, coords = Sobol(axes, 4, 3).layout(lambda n: {"units": "1"})
    assert dims == ("sample",) and shape == (4,) and coords["dc"][0] == "sample"
    assert coords["sample"][2]["long_name"] == "scenario drawn by sobol"
    with pytest.raises(ValueError, match="sample must be an integer >= 1"):
        Sobol(axes, 0)
    with pytest.raises(ValueError, match="axis 'dc' needs at least one value"):
        Grid({"dc": []})


def test_the_runner_takes_any_sampler_factory_and_metrics():
    """run_study on a Sobol sampler is the one runner with the FLL factory; the runner itself takes a user's
    factory and metrics and gives the same numbers on the same points."""
    import jax.numpy as jnp

    from jaxobs.runtime.runner import run_scenarios
    from jaxobs.scenarios import Sobol, grid_signals

    obs = linear.sogi_fll_closed_form()
    sampler = Sobol({"dc": [0.0, 0.1], "freq_step": [-1.0, 1.0]}, 4, seed=2)
    ds = run_study({"a": obs}, sampler, horizon=0.2, progress=False)
    assert ds["rms_phase_steady"].dims == ("design", "sample") and ds.attrs["sampling"] == "sobol"
    np.testing.assert_array_equal(ds["dc"].values, [p[0] for p in sampler.points()])
    steady = ds.attrs["steady_from"]

    def rms_phase(sol, _signal, _aux):
        return {"rms": M.rms(M.wrap(sol.outputs.obs.theta - sol.outputs.truth.theta), sol.t >= steady)}

    freq = float(obs.omega_n) / (2 * math.pi)
    run = run_scenarios(
        {"a": obs},
        sampler,
        jaxobs.OnSignal,
        rms_phase,
        horizon=0.2,
        build=lambda names, pts: grid_signals(names, pts, ds.attrs["t_event"], freq),
        chunk_size=3,  # two chunks, the last padded
    )
    np.testing.assert_allclose(run.values["a"]["rms"], ds["rms_phase_steady"].sel(design="a").values, rtol=1e-12)
    assert bool(jnp.all(jnp.isfinite(run.values["a"]["rms"])))


def test_scenarios_built_a_chunk_at_a_time_are_the_whole_batchs():
    """A builder that takes ``first`` is called per chunk with the index of the chunk's first point (the
    memory of the scenarios is one chunk's); its noise keys are the whole batch's, so a noisy
    study gives the same values in chunks of 3 as in one chunk, designs of two classes included; a bad axis
    value is refused before anything runs."""
    from jaxobs.runtime.runner import run_scenarios
    from jaxobs.scenarios import Random, grid_signals

    designs = {"SOGI-FLL": linear.sogi_fll_closed_form(), "WIF": linear.wif_closed_form()}
    sampler = Random({"noise": [0.0, 0.2], "freq_step": [-1.0, 1.0]}, 7, seed=3)
    one = run_study(designs, sampler, horizon=0.15, t_event=0.05, chunk_size=7, seed=5)
    chunks = run_study(designs, sampler, horizon=0.15, t_event=0.05, chunk_size=3, seed=5)
    for k in ("rms_phase_steady", "ripple_freq", "settling_freq"):
        np.testing.assert_array_equal(chunks[k].values, one[k].values)
    whole = grid_signals(sampler.names, sampler.points(), 0.05, 50.0, seed=5)
    calls = []

    def build(names, pts, first):
        calls.append((first, len(pts)))
        got = grid_signals(names, pts, 0.05, 50.0, seed=5, first=first)
        rows = min(len(pts), 7 - first)  # the padded rows copy the last point, not its key
        np.testing.assert_array_equal(np.asarray(got.key)[:rows], np.asarray(whole.key)[first : first + rows])
        return got

    run_scenarios(
        {"a": designs["WIF"]},
        sampler,
        jaxobs.OnSignal,
        lambda sol, _s, _a: {"w": sol.outputs.obs.omega[-1]},
        horizon=0.01,
        build=build,
        chunked=True,
        chunk_size=3,
    )
    assert calls == [(0, 3), (3, 3), (6, 3)]
    ran = []
    with pytest.raises(ValueError, match="grid axis sag must be <= 0.999"):
        run_study(designs, {"sag": [0.0, 0.5, 1.5]}, chunk_size=1, progress=lambda done, _n: ran.append(done))
    assert ran == []  # the last chunk's bad value, refused before the first chunk ran


def test_provenance_versions_and_digests(tmp_path):
    from jaxobs.io.provenance import provenance, sha256, versions

    v = versions()
    assert v["jax"] == jax.__version__ and v["numpy"] == np.__version__ and isinstance(v["x64"], bool)
    f = tmp_path / "a.toml"
    f.write_bytes(b"x = 1\n")
    assert sha256(f) == sha256(b"x = 1\n") == hashlib.sha256(b"x = 1\n").hexdigest()
    attrs = provenance("here", digests={"study": sha256(f)})
    assert attrs["source"] == "here" and attrs["study_sha256"] == sha256(f) and attrs["xarray_version"]
    assert attrs == provenance("here", digests={"study": sha256(f)})  # nothing that changes between runs


def test_given_and_recordings_samplers_hold_their_scenarios():
    """A batch given whole is laid out along its own dim, labelled; sizes and labels are checked."""
    import jax.numpy as jnp

    from jaxobs.scenarios import Given, Recordings

    batch = {"a": jnp.arange(3.0), "b": jnp.zeros((3, 2))}
    g = Given(batch, labels=["x", "y", "z"])
    assert g.points() == [(), (), ()] and g.scenarios(None, g.points()) is batch
    assert g.layout(lambda n: {"long_name": n}) == (
        ("scenario",),
        (3,),
        {"scenario": ("scenario", ["x", "y", "z"], {"long_name": "scenario"})},
    )
    with pytest.raises(ValueError, match="2 labels for 3 scenarios"):
        Given(batch, labels=["x", "y"])
    with pytest.raises(ValueError, match="one leading axis"):
        Given({"a": jnp.arange(3.0), "b": jnp.zeros(2)})
    rec = Recordings(batch, ["r1.csv", "r2.csv", "r3.csv"], ["0" * 64] * 3)
    assert rec.sampling == "recordings" and rec.layout(lambda n: {})[0] == ("recording",)
    with pytest.raises(ValueError, match="at least one recording"):
        Recordings(batch, [])

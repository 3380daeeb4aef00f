"""Traced programs kept across processes (jaxobs.kept_jit: a warm run skips tracing and lowering)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxobs
from jaxobs.runtime import programs as _traced


def _use(folder):
    """What a new process sees: a program cache on ``folder`` with nothing in memory."""
    jaxobs.set_program_cache(None if folder is None else jaxobs.ProgramCache(folder))


@pytest.fixture
def traced(tmp_path):
    before = _traced.program_cache()
    _use(tmp_path / "traced")
    yield tmp_path / "traced"
    jaxobs.set_program_cache(before)


class _Gain(eqx.Module):
    k: jax.Array
    n: int = eqx.field(static=True)


def _counted():
    calls = []

    def f(g, x):
        calls.append(1)  # runs only while tracing
        y = x
        for _ in range(g.n):
            y = jnp.sin(g.k * y) + jnp.exp(-y * y)
        return {"y": y, "s": (jnp.sum(y), jnp.cumsum(y))}

    return f, calls


def test_kept_equals_jit_and_a_new_process_does_not_trace(traced):
    g, x = _Gain(jnp.asarray(1.3), 3), jnp.linspace(-2.0, 2.0, 37)
    ref = eqx.filter_jit(_counted()[0])(g, x)
    f, calls = _counted()
    got = jaxobs.kept_jit(f)(g, x)
    assert jax.tree.structure(got) == jax.tree.structure(ref)
    for a, b in zip(jax.tree.leaves(got), jax.tree.leaves(ref)):
        assert np.array_equal(np.asarray(a), np.asarray(b))  # bit for bit
    assert len(list(traced.iterdir())) == 1 and calls == [1]
    # another process: a new kept_jit of new code objects reads the program back, never tracing f
    _use(traced)
    f2, calls2 = _counted()
    again = jaxobs.kept_jit(f2)(g, jnp.asarray(np.asarray(x) * 0.5))
    assert calls2 == []
    ref2 = eqx.filter_jit(_counted()[0])(g, x * 0.5)
    assert all(
        np.array_equal(np.asarray(a), np.asarray(b)) for a, b in zip(jax.tree.leaves(again), jax.tree.leaves(ref2))
    )


def test_kept_keys_on_shape_and_static_fields(traced):
    g, x = _Gain(jnp.asarray(1.3), 3), jnp.linspace(-2.0, 2.0, 37)
    jaxobs.kept_jit(_counted()[0])(g, x)
    jaxobs.kept_jit(_counted()[0])(g, x[:5])  # another shape
    f, calls = _counted()
    out = jaxobs.kept_jit(f)(_Gain(jnp.asarray(1.3), 2), x)  # a static field in the tree: another program
    assert calls == [1] and len(list(traced.iterdir())) == 3
    assert np.array_equal(np.asarray(out["y"]), np.asarray(eqx.filter_jit(_counted()[0])(_Gain(1.3, 2), x)["y"]))


def test_kept_off_without_folder_and_unexportable_falls_back(tmp_path, traced):
    g, x = _Gain(jnp.asarray(0.7), 1), jnp.arange(4.0)
    _use(None)
    f, calls = _counted()
    k = jaxobs.kept_jit(f)
    k(g, x), k(g, x)
    assert calls == [1] and not traced.exists()  # a plain jit: traced once in this process, nothing written
    _use(traced)
    out = jaxobs.kept_jit(lambda g, x: _Gain(g.k * x, 2))(g, x)  # an output of a custom class
    assert isinstance(out, _Gain) and np.array_equal(np.asarray(out.k), np.asarray(g.k * x))
    assert not traced.exists() or not list(traced.iterdir())


def test_kept_corrupt_file_is_exported_again(traced, capsys):
    g, x = _Gain(jnp.asarray(1.1), 2), jnp.linspace(0.0, 1.0, 9)
    jaxobs.kept_jit(_counted()[0])(g, x)
    (path,) = traced.iterdir()
    path.write_bytes(b"not a program")
    _use(traced)  # another process
    f, calls = _counted()
    out = jaxobs.kept_jit(f)(g, x)
    assert calls == [1] and path.stat().st_size > 100
    assert np.array_equal(np.asarray(out["y"]), np.asarray(eqx.filter_jit(_counted()[0])(g, x)["y"]))
    assert "corrupt" in capsys.readouterr().err


@pytest.mark.parametrize("change", ["jaxobs source", "own source", "library version", "jax option", "none"])
def test_a_stale_program_is_never_reused(traced, monkeypatch, change):
    """A later process with an edited jaxobs, an edited defining module, another library version or another JAX
    option that changes a trace traces the program again under a new key; with nothing changed it reads it back."""
    g, x = _Gain(jnp.asarray(1.3), 2), jnp.linspace(-2.0, 2.0, 9)
    jaxobs.kept_jit(_counted()[0])(g, x)
    _use(traced)  # a later process
    top = __name__.split(".")[0]
    memo = {"jaxobs source": "jaxobs", "own source": top, "library version": "versions:"}.get(change)
    if memo is not None:
        monkeypatch.setitem(_traced._memo, memo, _traced._memo[memo] + "-edited")
    f, calls = _counted()
    debug = jax.config.values["jax_debug_infs"]
    jax.config.update("jax_debug_infs", change == "jax option" or debug)
    try:
        out = jaxobs.kept_jit(f)(g, x)
    finally:
        jax.config.update("jax_debug_infs", debug)
    assert calls == ([] if change == "none" else [1])
    assert len(list(traced.iterdir())) == (1 if change == "none" else 2)
    assert np.array_equal(np.asarray(out["y"]), np.asarray(eqx.filter_jit(_counted()[0])(g, x)["y"]))


def test_use_compile_cache_sets_the_traced_folder(tmp_path, monkeypatch):
    before = (jax.config.jax_compilation_cache_dir, jax.config.jax_persistent_cache_min_compile_time_secs)
    kept = _traced.program_cache()
    try:
        assert jaxobs.use_compile_cache(tmp_path / "c") == tmp_path / "c"
        assert _traced.program_cache().folder == tmp_path / "c" / "traced"
        assert (tmp_path / "c").stat().st_mode & 0o777 == 0o700  # the user's alone
        jaxobs.use_compile_cache(tmp_path / "d", keep_traces=False)
        assert _traced.program_cache().folder is None
    finally:
        jax.config.update("jax_compilation_cache_dir", before[0])
        jax.config.update("jax_persistent_cache_min_compile_time_secs", before[1])
        jaxobs.set_program_cache(kept)


def test_the_folder_keeps_the_most_recently_used(traced, monkeypatch):
    """A new entry trims the folder to max_kept: the least recently used go, and a killed writer's temp file (over
    an hour old), but not a live writer's."""
    import os

    traced.mkdir()
    for i in range(5):
        f = traced / f"{i}.jaxexport"
        f.write_bytes(b"x")
        os.utime(f, (1000 + i, 1000 + i))
    os.utime(traced / "0.jaxexport", (2000, 2000))  # read back lately
    old, live = traced / ".a.jaxexport.0123456789ab.tmp", traced / ".b.jaxexport.456789abcdef.tmp"
    for p in (old, live):
        p.write_bytes(b"x")
    os.utime(old, (1000, 1000))
    monkeypatch.setattr(_traced, "MAX_KEPT", 3)
    _use(traced)
    jaxobs.kept_jit(_counted()[0])(_Gain(jnp.asarray(0.5), 1), jnp.arange(3.0))
    names = sorted(f.name for f in traced.iterdir())
    assert len(names) == 4 and names[:3] == [live.name, "0.jaxexport", "4.jaxexport"]


def test_a_reproduction_run_is_kept_with_its_namedtuple_outputs(traced, monkeypatch):
    """jaxobs.reproduce._run.run_kept returns a run's step outputs, NamedTuples nested in NamedTuples: exported
    (a program written, not the plain-jit fallback) and read back by a later process, bit for bit simulate's
    t, outputs and ok.  An FLL on a grid signal (SignalOutput of FLLOutput and SignalTruth): a cheap compile."""
    from jaxobs.reproduce import _run

    obs = jaxobs.SOGIFLL(1.2, 4e4, ts=1e-4)  # any gains: the program, not the design, is under test
    system = jaxobs.OnSignal(obs, jaxobs.GridSignal(1.0, 50.5, t_event=0.005, freq_step=1.0))
    ref = jaxobs.simulate(system, 0.01)
    monkeypatch.setattr(_run, "_simulated_kept", jaxobs.kept_jit(_run._simulated))
    got = _run.run_kept(system, 0.01)
    assert len(list(traced.iterdir())) == 1  # exported: the outputs' NamedTuples are registered
    _use(traced)  # a later process: read back, not traced
    monkeypatch.setattr(_run, "_simulated_kept", jaxobs.kept_jit(_run._simulated))
    monkeypatch.setattr(_run, "simulate", lambda *a: pytest.fail("traced again"))
    again = _run.run_kept(system, 0.01)
    for run in (got, again):
        assert jax.tree.structure(run.outputs) == jax.tree.structure(ref.outputs)
        for a, b in zip(jax.tree.leaves((run.t, run.outputs, run.ok)), jax.tree.leaves((ref.t, ref.outputs, ref.ok))):
            assert np.array_equal(np.asarray(a), np.asarray(b))  # bit for bit
    assert len(list(traced.iterdir())) == 1


@pytest.mark.parametrize("machine", ["single", "dual"])
def test_the_reproductions_drive_outputs_are_exportable(machine):
    """Every NamedTuple a reproduction's drive run returns (DriveOutput or DualOutput, with the bank's, the
    FOC's and the plant's outputs inside) is registered for jax.export (jaxobs.reproduce._run): the program
    is exported and its outputs' tree comes back from the serialized bytes.  Traced and lowered, not compiled."""
    from jax import export

    from jaxobs import drive as D
    from jaxobs.reproduce import _run  # noqa: F401  (registers the NamedTuples)
    from jaxobs.reproduce.leso import leso_bank

    if machine == "single":
        par = D.bench_machine("ipmsm002")
        sc = D.Scenario(par, speed_ref=D.Profile.constant(300 * D.RPM), omega_m0=300 * D.RPM)
        system = D.ClosedLoop(D.bench_drive(par, handover=0.001), leso_bank(par, par.p * 300 * D.RPM), sc)
    else:
        m = D.dual_ipmsm_paper002()
        est = m.per_set()
        sc = D.Scenario(est, speed_ref=D.Profile.constant(300 * D.RPM), omega_m0=300 * D.RPM)
        drive = D.dual_bench_drive(m, mode="vsd", sensorless=True, handover=0.001)
        system = D.DualClosedLoop(drive, leso_bank(est, m.p * 300 * D.RPM), sc, m)
    dyn, static = eqx.partition(system, eqx.is_array)
    leaves, tree = jax.tree.flatten(dyn)

    def run(*xs):  # as kept_jit exports: the arguments flattened, the outputs as run_kept returns them
        sol = jaxobs.simulate(eqx.combine(jax.tree.unflatten(tree, xs), static), 0.001)
        return sol.t, sol.outputs, sol.ok

    exp = export.export(jax.jit(run))(*leaves)
    back = export.deserialize(exp.serialize())
    assert back.out_tree == exp.out_tree
    outputs = back.out_tree.unflatten(range(back.out_tree.num_leaves))[1]
    assert type(outputs).__name__ == ("DriveOutput" if machine == "single" else "DualOutput")

"""Where compile time goes, by program: the drive's step, its ``jvp`` and ``vjp``, a scan over it, the Floquet
verdict's tangent block, and the verdict itself.

    python -m benchmarks.programs [--json PATH]

Each program is jitted alone in this process, on the ``ipmsm002`` bench drive with the FA-LESO closing it
(float64, one scenario at 600 r/min), and timed in its three stages: *trace* (Python → jaxpr, ``jit.trace``),
*lower* (jaxpr → StableHLO, ``.lower()``) and *compile* (XLA, ``.compile()``), with the persistent
compilation cache off (every program compiles).  Its size is counted twice: the StableHLO ops it is lowered to
(the program as JAX hands it over) and the HLO instructions of the optimized module XLA compiled (after
inlining, unrolling and fusion: what the compile time follows).  The 1-minute load average is printed with the
table: on a busy machine every time grows, the sizes do not.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import time


def _count_stablehlo(text: str) -> int:
    """The StableHLO/func operations of a lowered module (one per ``=`` assignment or a bare ``stablehlo.`` /
    ``func.return`` op line)."""
    return sum(1 for line in text.splitlines() if re.search(r"\b(stablehlo|chlo|func|mhlo)\.[a-z_]+", line))


def _count_hlo(text: str) -> int:
    """The instructions of an optimized HLO module (its lines of the form ``name = type op(...)``)."""
    return sum(1 for line in text.splitlines() if re.match(r"\s*(ROOT\s+)?[%\w.\-]+\s*=\s*\S", line))


def _profile(name: str, fn, *args) -> dict:
    import jax

    t0 = time.perf_counter()
    traced = jax.jit(fn).trace(*args)
    t1 = time.perf_counter()
    lowered = traced.lower()
    t2 = time.perf_counter()
    compiled = lowered.compile()
    t3 = time.perf_counter()
    return dict(
        program=name,
        stablehlo_ops=_count_stablehlo(lowered.as_text()),
        hlo_instructions=_count_hlo(compiled.as_text()),
        trace_s=round(t1 - t0, 3),
        lower_s=round(t2 - t1, 3),
        compile_s=round(t3 - t2, 3),
    )


def measure() -> list[dict]:
    """The rows, one per program (module doc)."""
    import jax

    jax.config.update("jax_enable_x64", True)
    jax.config.update("jax_enable_compilation_cache", False)
    import jax.numpy as jnp
    from jax.flatten_util import ravel_pytree

    import jaxobs
    from jaxobs.analysis.stability import floquet
    from jaxobs.drive import RPM, ClosedLoop, Profile, Scenario, bench_drive, bench_machine
    from jaxobs.observers import FALESO

    par = bench_machine("ipmsm002")
    drive = bench_drive(par, sensorless=True, handover=0.0)
    sc = Scenario(par, speed_ref=Profile.constant(600 * RPM), omega_m0=600 * RPM)
    obs = FALESO.closed_form(ts=drive.ts).bind(par, par.p * 600 * RPM)
    loop = ClosedLoop(drive, obs, sc)
    state = loop.init()
    dyn, rest = jaxobs_partition(state)
    vec, unravel = ravel_pytree(dyn)
    k = jnp.asarray(7)

    def step_vec(v, loop):
        s, out = loop.step(combine(unravel(v), rest), k)
        return ravel_pytree(jaxobs_partition(s)[0])[0], out.theta_e_hat

    def step(loop, state):
        return loop.step(state, k)

    def jvp(loop, v, d):
        return jax.jvp(lambda vv: step_vec(vv, loop), (v,), (d,))

    def vjp(loop, v, ct):
        _, back = jax.vjp(lambda vv: step_vec(vv, loop)[0], v)
        return back(ct)

    def run200(loop):
        return jaxobs.simulate(loop, 200 * drive.ts).outputs.theta_e_hat

    def tangent_block(loop, v):
        # the Floquet verdict's inner block: every state direction (n of them) through one step's jvp
        eye = jnp.eye(v.shape[0])
        return jax.vmap(lambda d: jax.jvp(lambda vv: step_vec(vv, loop), (v,), (d,))[1][0], in_axes=1)(eye)

    def verdict(loop):
        return floquet(loop, settle=0.05, window=0.05, max_window=0.1).exponent

    rows = [
        _profile("drive step (value)", step, loop, state),
        _profile("drive step, jvp (one direction)", jvp, loop, vec, jnp.ones_like(vec)),
        _profile("drive step, vjp", vjp, loop, vec, jnp.ones_like(vec)),
        _profile("simulate, 200 steps (scan of the step)", run200, loop),
        _profile(f"Floquet tangent block ({vec.shape[0]} directions, one step)", tangent_block, loop, vec),
        _profile("Floquet verdict (settle, window, eigenvalues)", verdict, loop),
    ]
    return rows


def jaxobs_partition(state):
    import equinox as eqx

    return eqx.partition(state, eqx.is_inexact_array)


def combine(dyn, rest):
    import equinox as eqx

    return eqx.combine(dyn, rest)


def table(rows: list[dict]) -> str:
    cols = ("program", "StableHLO ops", "optimized HLO instructions", "trace s", "lower s", "compile s")
    head = "| " + " | ".join(cols) + " |\n" + "|---" * len(cols) + "|"
    lines = [
        f"| {r['program']} | {r['stablehlo_ops']} | {r['hlo_instructions']} | {r['trace_s']:.2f} | "
        f"{r['lower_s']:.2f} | {r['compile_s']:.2f} |"
        for r in rows
    ]
    return "\n".join([head, *lines])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", help="write the rows here as JSON")
    a = ap.parse_args(argv)
    load0 = os.getloadavg()[0]
    rows = measure()
    load1 = os.getloadavg()[0]
    print(table(rows))
    print(f"\nload average (1 min): {load0:.1f} at the start, {load1:.1f} at the end")
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"rows": rows, "load": [load0, load1]}, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

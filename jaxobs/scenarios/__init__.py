"""Scenario samplers and builders: which points of the named axes a study runs, and the batched signals.

One place, below both the studies (:mod:`jaxobs.studies.study`, :mod:`jaxobs.studies.drive`) and the tuning jobs
(``tuning/``).  A *sampler* picks the points of the axes and says how the results are laid out
(:class:`Grid`: the Cartesian product, one dim per axis; :class:`Random`, :class:`Sobol`, :class:`LHS`:
``n`` points inside the axes' [min, max], one ``sample`` dim with the axes as coordinates along it;
:class:`Given`: a batch given whole, one ``scenario`` dim; :class:`Recordings`: recorded signals, one
``recording`` dim); a *builder* turns the points into a
batched scenario PyTree (:func:`grid_signals` here, :func:`jaxobs.drive.scenario_batch` for the drive), and
:func:`jaxobs.runtime.runner.run_scenarios` runs every design on it.

Grid signals (the FLL family): single-phase :class:`~jaxobs.GridSignal` s with an event
at ``t_event`` plus optional white noise.  Axes (:data:`GRID_SIGNAL_AXES`):
``freq_step`` (Hz), ``phase_jump_deg``, ``sag`` (depth), ``dc``, ``harmonics_scale``
(× 001 Test C's spectrum, :data:`jaxobs.papers.TEST_C_HARMONICS`), ``sub_amplitude``
(1 Hz), ``phase_deg`` (initial phase) and ``noise`` (white noise standard deviation,
p.u., with a per-scenario seed).

EMF signals (the flux observers without a drive): two-axis :class:`~jaxobs.EMFSignal` s.  Axes
(:data:`EMF_SIGNAL_AXES`): ``speed_hz`` (electrical frequency), ``dc_alpha``, ``dc_beta`` (V),
``h5``, ``h7`` (× the fundamental) and ``phase_deg``.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import PyTree

from ..core.quantities import Axis
from ..core.sampletime import SampleTime, Time, TimeLike, time_value
from ..papers import TEST_C_HARMONICS
from ..signals import AbstractSignal, EMFSignal, GridSignal, stack

__all__ = [
    "EMF_SIGNAL_AXES",
    "GRID_SIGNAL_AXES",
    "LHS",
    "AbstractSampler",
    "Given",
    "Grid",
    "NoisyGridSignal",
    "Random",
    "Recordings",
    "Sobol",
    "emf_signals",
    "grid_signals",
    "sampler_of",
    "SAMPLINGS",
]

# the grid signals' axes (the FLL family): one Axis each (CF units, the range a study or a job may give)
GRID_SIGNAL_AXES: dict[str, Axis] = {
    a.name: a
    for a in (
        Axis("freq_step", "Hz", (-1e4, 1e4), "frequency step at the event"),
        Axis("phase_jump_deg", "degree", (-360.0, 360.0), "phase jump at the event"),
        Axis("sag", "1", (0.0, 0.999), "voltage sag depth at the event (p.u.)"),
        Axis("dc", "1", (-10.0, 10.0), "dc offset (p.u. of the fundamental)"),
        Axis("harmonics_scale", "1", (0.0, 100.0), "harmonic distortion (multiple of 001 Test C's spectrum)"),
        Axis("sub_amplitude", "1", (0.0, 10.0), "1 Hz subharmonic amplitude (p.u.)"),
        Axis("phase_deg", "degree", (-360.0, 360.0), "initial phase"),
        Axis("noise", "1", (0.0, 10.0), "white measurement noise standard deviation (p.u.)"),
    )
}


class NoisyGridSignal(AbstractSignal):
    """A :class:`GridSignal` plus white measurement noise (std ``noise``, seeded per scenario).

    The noise of sample k is drawn from ``fold_in(key, k)``: white in time, the same sample for the
    same k however the loop evaluates it (one step at a time, or a block of steps at once).  Given a
    float time instead of a :class:`~jaxobs.SampleTime` (no sample index), one independent draw per
    element of ``t`` is made from ``key``.

    Attributes:
        clean: The :class:`GridSignal`.
        noise: The noise's standard deviation, in the signal's units.
        key: The PRNG key of the scenario's noise.
        accepts_sample_time: True: passed on to the clean signal (exact float32 phase).
        has_truth: True: the clean signal's.
    """

    clean: GridSignal
    noise: jax.Array | np.ndarray  # NumPy in the template grid_signals broadcasts, JAX once batched
    key: jax.Array | np.ndarray

    accepts_sample_time: ClassVar[bool] = True  # passed on to the clean signal (exact float32 phase)
    has_truth: ClassVar[bool] = True  # the clean signal's

    def __call__(self, t):
        tv = time_value(t)
        dtype = jnp.result_type(tv)
        if isinstance(t, SampleTime):
            k = jnp.asarray(t.k)
            draw = lambda kk: jax.random.normal(jax.random.fold_in(self.key, kk), (), dtype=dtype)  # noqa: E731
            n = draw(k) if k.ndim == 0 else jax.vmap(draw)(k.ravel()).reshape(k.shape)
        else:
            n = jax.random.normal(self.key, jnp.shape(tv), dtype=dtype)
        return self.clean(t) + self.noise * n

    def theta(self, t: TimeLike) -> Time:
        """The phase, rad, of the clean signal at ``t``.

        Args:
            t: The time, s, or a :class:`~jaxobs.SampleTime`.

        Returns:
            The phase, rad.
        """
        return self.clean.theta(t)

    def omega(self, t: TimeLike) -> Time:
        """The angular frequency, rad/s, of the clean signal at ``t``.

        Args:
            t: The time, s, or a :class:`~jaxobs.SampleTime`.

        Returns:
            The angular frequency, rad/s.
        """
        return self.clean.omega(t)

    def fundamental_amplitude(self, t: TimeLike) -> Time:
        """The fundamental's amplitude of the clean signal at ``t``.

        Args:
            t: The time, s, or a :class:`~jaxobs.SampleTime`.

        Returns:
            The fundamental's amplitude.
        """
        return self.clean.fundamental_amplitude(t)


_AXIS_LOWER = {"sag": 0.0, "harmonics_scale": 0.0, "sub_amplitude": 0.0, "noise": 0.0}


def grid_signals(
    names: Sequence[str],
    combos: Sequence[Sequence[float]],
    t_event: float,
    freq: float,
    *,
    seed: int = 0,
    first: int = 0,
) -> NoisyGridSignal:
    """Batched :class:`NoisyGridSignal` for ``combos``.

    Vectorized — the leaves are set as arrays, no constructor runs per scenario — and
    checked as :class:`GridSignal` would check one scenario.  Shared by studies
    (:func:`jaxobs.studies.study.run_study`) and by tuning jobs on grid signals.

    Args:
        names: The axes, of :data:`GRID_SIGNAL_AXES`.
        combos: One tuple of values per scenario, in ``names`` order.
        t_event: The event's time, s.
        freq: The nominal frequency, Hz.
        seed: Scenario i's noise key is ``fold_in(PRNGKey(seed), i)``: the study's (or job's) seed drives
            its noise.
        first: The index of ``combos[0]`` among all the scenarios (a chunk built on its own has the keys it
            has in the whole).

    Returns:
        The batched :class:`NoisyGridSignal` (leading axis one per scenario).

    Raises:
        ValueError: An unknown axis or a value out of its range, naming the axis.
    """
    names = list(names)
    for name in names:
        if name not in GRID_SIGNAL_AXES:
            raise ValueError(f"grid axis {name!r} is unknown; known axes: {', '.join(GRID_SIGNAL_AXES)}")
    n = len(combos)
    for i, name in enumerate(names):
        col = np.asarray([c[i] for c in combos], dtype=float)
        if not np.all(np.isfinite(col)):
            raise ValueError(f"grid axis {name} must be finite")
        if name in _AXIS_LOWER and np.any(col < _AXIS_LOWER[name]):
            raise ValueError(f"grid axis {name} must be >= 0, got {col.min():g}")
        if name == "sag" and np.any(col > 0.999):
            raise ValueError(f"grid axis sag must be <= 0.999 (a sag depth), got {col.max():g}")
        if name == "freq_step" and np.any(freq + col <= 0):
            raise ValueError(
                f"grid axis freq_step must keep the frequency > 0 Hz, got freq + freq_step = {freq + col.min():g}"
            )
    clean = GridSignal(freq=freq, t_event=t_event, harmonics={h: 0.0 for h in TEST_C_HARMONICS})
    base = NoisyGridSignal(clean, np.zeros(()), np.zeros((2,), np.uint32))
    # the batch is built in NumPy and put on the device once at the end: eagerly, each jnp broadcast and
    # conversion here compiled a small XLA program of its own on a first run
    batched = jax.tree.map(lambda x: np.broadcast_to(np.asarray(x), (n,) + np.shape(x)), base)
    cols = {name: np.asarray([c[i] for c in combos], dtype=float) for i, name in enumerate(names)}
    c = batched.clean
    if "freq_step" in cols:
        c = eqx.tree_at(lambda s: s.freq_step, c, cols["freq_step"])
    if "phase_jump_deg" in cols:
        c = eqx.tree_at(lambda s: s.phase_jump, c, np.radians(cols["phase_jump_deg"]))
    if "sag" in cols:
        c = eqx.tree_at(lambda s: s.sag, c, cols["sag"])
    if "dc" in cols:
        c = eqx.tree_at(lambda s: s.dc, c, cols["dc"])
    if "harmonics_scale" in cols:
        mags = np.asarray([TEST_C_HARMONICS[h] for h in c.orders])
        c = eqx.tree_at(lambda s: s.harmonics, c, cols["harmonics_scale"][:, None] * mags[None, :])
    if "sub_amplitude" in cols:
        c = eqx.tree_at(lambda s: s.sub_amplitude, c, cols["sub_amplitude"])
    if "phase_deg" in cols:
        c = eqx.tree_at(lambda s: s.phase, c, np.radians(cols["phase_deg"]))
    out = eqx.tree_at(lambda s: s.clean, batched, c)
    if "noise" in cols:
        out = eqx.tree_at(lambda s: s.noise, out, cols["noise"])
    real = jnp.result_type(float)  # float64 with jax_enable_x64, else float32: what jnp.asarray gave
    out = jax.tree.map(lambda x: jax.device_put(x.astype(real) if np.issubdtype(x.dtype, np.floating) else x), out)
    return eqx.tree_at(lambda s: s.key, out, _noise_keys(seed, first, n))


@functools.partial(jax.jit, static_argnums=2)
def _noise_keys(seed, first, n: int):
    """Scenario i's noise key ``fold_in(PRNGKey(seed), first + i)`` for i < n: one program per batch size."""
    return jax.vmap(lambda i: jax.random.fold_in(jax.random.PRNGKey(seed), i))(first + jnp.arange(n))


# the back EMFs' axes (the flux observers without a drive)
EMF_SIGNAL_AXES: dict[str, Axis] = {
    a.name: a
    for a in (
        Axis("speed_hz", "Hz", (1e-3, 1e4), "electrical frequency of the back EMF (100 V at 50 Hz)"),
        Axis("dc_alpha", "V", (-1e4, 1e4), "dc offset of the back EMF, alpha axis"),
        Axis("dc_beta", "V", (-1e4, 1e4), "dc offset of the back EMF, beta axis"),
        Axis("h5", "1", (0.0, 10.0), "negative-sequence 5th harmonic (multiple of the fundamental)"),
        Axis("h7", "1", (0.0, 10.0), "positive-sequence 7th harmonic (multiple of the fundamental)"),
        Axis("phase_deg", "degree", (-360.0, 360.0), "initial phase"),
    )
}


def emf_signals(names: Sequence[str], combos: Sequence[Sequence[float]]) -> EMFSignal:
    """Batched :class:`~jaxobs.EMFSignal` for ``combos``.

    A back EMF proportional to speed, 100 V at 50 Hz (``speed_hz``, default 50 Hz), with dc offsets
    ``dc_alpha``, ``dc_beta`` (V), a negative-sequence 5th and a positive-sequence 7th harmonic of ``h5``,
    ``h7`` × the fundamental, from the initial phase ``phase_deg``.

    Args:
        names: The axes, of :data:`EMF_SIGNAL_AXES`.
        combos: One tuple of values per scenario, in ``names`` order.

    Returns:
        The batched :class:`~jaxobs.EMFSignal` (leading axis one per scenario).

    Raises:
        ValueError: An unknown axis (naming it), or a value :class:`~jaxobs.EMFSignal` refuses.
    """
    names = list(names)
    for name in names:
        if name not in EMF_SIGNAL_AXES:
            raise ValueError(f"EMF axis {name!r} is unknown; known axes: {', '.join(EMF_SIGNAL_AXES)}")
    sigs = []
    for combo in combos:
        a = dict(zip(names, combo))
        f = a.get("speed_hz", 50.0)
        sigs.append(
            EMFSignal(
                A1=100.0 * f / 50.0,  # BEMF ∝ speed: 100 V at 50 Hz
                omega1=2 * math.pi * f,
                phase=math.radians(a.get("phase_deg", 0.0)),
                dc=(a.get("dc_alpha", 0.0), a.get("dc_beta", 0.0)),
                harmonics={-5: a.get("h5", 0.0) * 100.0 * f / 50.0, 7: a.get("h7", 0.0) * 100.0 * f / 50.0},
            )
        )
    return stack(sigs)


# --------------------------------------------------------------------------
# samplers: which points of the axes a study runs, and how its results are laid out
# --------------------------------------------------------------------------


def _axes_dict(axes) -> dict:
    if not isinstance(axes, dict) or not axes:
        raise ValueError("sampler axes must be a non-empty dict of axis name -> list of values")
    out = {}
    for name, vals in axes.items():
        vals = np.asarray(vals, dtype=float).reshape(-1)
        if vals.size < 1:
            raise ValueError(f"study axis {name!r} needs at least one value")
        out[str(name)] = vals
    return out


AxisMeta = Callable[[str], dict[str, str]]  # an axis's attributes (units, long_name) by its name
Builder = Callable[[tuple, list], PyTree]  # build(names, points): a family's batched scenarios of its points
Layout = tuple[tuple, tuple, dict]  # (dims after design, the shape of the per-scenario values, the coordinates)


class AbstractSampler:
    """The points of a study.

    ``points()`` gives one tuple of values per scenario, in ``names`` order; ``layout(axis_meta)`` the dims
    after ``design``, the shape the per-scenario values take, and the coordinates, each with the attributes
    ``axis_meta(name)`` gives (``units``, ``long_name``).

    Attributes:
        names: The axes.
        sampling: The Dataset's ``sampling`` attribute.
        dim_attrs: The attributes of a dim of its own (a :class:`Given` batch's), which no family's axis names.
    """

    names: tuple
    sampling: str
    dim_attrs: ClassVar[dict] = {}

    def points(self) -> list[tuple]:
        """The points, one tuple of values per scenario in ``names`` order."""
        raise NotImplementedError

    def array(self) -> np.ndarray:
        """The points as one (n, axes) float array: 8 bytes a value where :meth:`points` holds a tuple of
        Python floats (about 180 bytes a scenario of four axes); what :func:`jaxobs.runtime.runner.run_scenarios`
        keeps while a study runs."""
        pts = self.points()
        return np.asarray(pts, dtype=float).reshape(len(pts), len(self.names))

    def layout(self, axis_meta: AxisMeta) -> Layout:
        """How the results are laid out: the dims after ``design``, the shape the per-scenario values take, and the
        coordinates ``{name: (dim, values, attributes)}``.

        Args:
            axis_meta: An axis's attributes (``units``, ``long_name``) by its name.

        Returns:
            (dims, shape, coordinates).
        """
        raise NotImplementedError

    def scenarios(self, build: Builder | None, points: list) -> PyTree:
        """The batched scenario PyTree of ``points`` (this sampler's): ``build(names, points)``.

        Args:
            build: ``build(names, points)``, the scenario builder.
            points: Points of this sampler.

        Returns:
            The batched scenario PyTree.

        Raises:
            ValueError: No ``build``.
        """
        if build is None:
            raise ValueError(f"a {type(self).__name__} sampler needs a scenario builder (build=...)")
        return build(self.names, points)


@dataclass(frozen=True, eq=False)
class Grid(AbstractSampler):
    """Every combination of the axes' values (row-major: the last axis fastest); dims = the axes.

    Args:
        axes: ``{axis name: values}``, each with at least one value.

    Raises:
        ValueError: An empty ``axes``, or an axis without values.
    """

    axes: dict
    sampling: ClassVar[str] = "grid"

    def __post_init__(self):
        object.__setattr__(self, "axes", _axes_dict(self.axes))

    @property
    def names(self) -> tuple:
        """The axes, in ``axes`` order."""
        return tuple(self.axes)

    def points(self) -> list[tuple]:
        """Every combination of the axes' values, the last axis fastest."""
        return list(itertools.product(*(list(map(float, self.axes[n])) for n in self.names)))

    def array(self) -> np.ndarray:
        """The points as one (n, axes) float array, in :meth:`points`' order."""
        # itertools.product's order (the last axis fastest), without a tuple per point
        cols = np.meshgrid(*(np.asarray(self.axes[n], dtype=float) for n in self.names), indexing="ij")
        return np.stack([c.reshape(-1) for c in cols], axis=1)

    def layout(self, axis_meta: AxisMeta) -> Layout:
        """The axes as dims, each with its values as the coordinate (:meth:`AbstractSampler.layout`).

        Args:
            axis_meta: An axis's attributes (``units``, ``long_name``) by its name.

        Returns:
            (dims, shape, coordinates).
        """
        shape = tuple(len(self.axes[n]) for n in self.names)
        coords = {n: (n, np.asarray(self.axes[n], dtype=float), axis_meta(n)) for n in self.names}
        return self.names, shape, coords


@dataclass(frozen=True, eq=False)
class _Drawn(AbstractSampler):
    """``n`` points inside the axes' [min, max]; one ``sample`` dim, the axes as coordinates along it."""

    axes: dict
    n: int
    seed: int = 0
    sample_long_name: ClassVar[str] = "scenario drawn at random"

    def __post_init__(self):
        object.__setattr__(self, "axes", _axes_dict(self.axes))
        if isinstance(self.n, bool) or not isinstance(self.n, (int, np.integer)) or self.n < 1:
            raise ValueError(f"sample must be an integer >= 1 with sampling={self.sampling!r}, got {self.n!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)):
            raise ValueError(f"seed must be an integer, got {self.seed!r}")

    @property
    def names(self) -> tuple:
        return tuple(self.axes)

    def _bounds(self):
        lo = np.array([self.axes[k].min() for k in self.names], dtype=float)
        hi = np.array([self.axes[k].max() for k in self.names], dtype=float)
        return lo, hi

    def array(self) -> np.ndarray:
        """The points as one (n, axes) float array (8 bytes a value; :meth:`points` is these rows as tuples)."""
        raise NotImplementedError

    def points(self) -> list[tuple]:
        """The points drawn, as tuples (:meth:`array`'s rows)."""
        return list(map(tuple, self.array().tolist()))

    def layout(self, axis_meta: AxisMeta) -> Layout:
        """One ``sample`` dim, the axes as coordinates along it (:meth:`AbstractSampler.layout`).

        Args:
            axis_meta: An axis's attributes (``units``, ``long_name``) by its name.

        Returns:
            (dims, shape, coordinates).
        """
        # the coordinates straight from the array: a list of n tuples of Python floats took ~180 bytes a
        # scenario, at the end of a study where its values are held too (the peak of a 10⁶-scenario study)
        pts = self.array()
        coords = {"sample": ("sample", np.arange(len(pts)), {"units": "1", "long_name": self.sample_long_name})}
        for i, k in enumerate(self.names):
            coords[k] = ("sample", np.ascontiguousarray(pts[:, i]), axis_meta(k))
        return ("sample",), (len(pts),), coords


class Random(_Drawn):
    """``n`` points drawn uniformly (``numpy.random.default_rng(seed)``, one axis after another per point).

    Args:
        axes: ``{axis name: values}``; each axis is drawn between its values' minimum and maximum.
        n: The number of points (an integer ≥ 1).
        seed: The generator's seed (an integer).

    Raises:
        ValueError: An empty ``axes``, an axis without values, ``n`` < 1 or a seed that is not an integer.
    """

    sampling: ClassVar[str] = "random"

    def array(self) -> np.ndarray:
        """The points drawn uniformly, (n, axes)."""
        # one vectorized draw: the same numbers as n × axes scalar draws in that order (row-major), without a
        # Python loop over the points
        lo, hi = self._bounds()
        return np.random.default_rng(self.seed).uniform(lo, hi, size=(self.n, len(self.names)))


def _qmc_points(self, u) -> np.ndarray:
    lo, hi = self._bounds()
    # u · (hi − lo) + lo, the arithmetic of scipy.stats.qmc.scale, which refuses an axis of one value
    # (min = max); such an axis stays at its value
    return u * (hi - lo) + lo


class Sobol(_Drawn):
    """``n`` points of a scrambled Sobol sequence (``scipy.stats.qmc.Sobol``, seeded by ``seed``).

    Args:
        axes: ``{axis name: values}``; each axis is drawn between its values' minimum and maximum.
        n: The number of points (an integer ≥ 1).
        seed: The generator's seed (an integer).

    Raises:
        ValueError: An empty ``axes``, an axis without values, ``n`` < 1 or a seed that is not an integer.
    """

    sampling: ClassVar[str] = "sobol"
    sample_long_name: ClassVar[str] = "scenario drawn by sobol"

    def array(self) -> np.ndarray:
        """The points of the scrambled Sobol sequence, (n, axes)."""
        from scipy.stats import qmc

        # scipy's rng renaming decorator keeps seed=, which its stubs do not show
        sobol = qmc.Sobol(len(self.names), scramble=True, seed=self.seed)  # pyright: ignore[reportCallIssue]
        return _qmc_points(self, sobol.random(self.n))


class LHS(_Drawn):
    """``n`` points of a Latin hypercube (``scipy.stats.qmc.LatinHypercube``, seeded by ``seed``).

    Args:
        axes: ``{axis name: values}``; each axis is drawn between its values' minimum and maximum.
        n: The number of points (an integer ≥ 1).
        seed: The generator's seed (an integer).

    Raises:
        ValueError: An empty ``axes``, an axis without values, ``n`` < 1 or a seed that is not an integer.
    """

    sampling: ClassVar[str] = "lhs"
    sample_long_name: ClassVar[str] = "scenario drawn by lhs"

    def array(self) -> np.ndarray:
        """The points of the Latin hypercube, (n, axes)."""
        from scipy.stats import qmc

        # scipy's rng renaming decorator keeps seed=, which its stubs do not show
        lhs = qmc.LatinHypercube(len(self.names), seed=self.seed)  # pyright: ignore[reportCallIssue]
        return _qmc_points(self, lhs.random(self.n))


class Given(AbstractSampler):
    """Scenarios given whole, laid out along one dim.

    Args:
        batch: A batched scenario PyTree (leading axis one per scenario).
        labels: The dim's coordinate, one per scenario (default 0, 1, ...).
        dim: The dim's name.

    Raises:
        ValueError: The leaves disagree on the leading axis, or the labels are not one per scenario.
    """

    names: ClassVar[tuple] = ()
    sampling: ClassVar[str] = "given"
    # the dim's attributes, where the family has no axis of its name (jaxobs.studies.study.study)
    dim_attrs: ClassVar[dict] = {"units": "1", "long_name": "scenario given whole (jaxobs.scenarios.Given)"}

    def __init__(self, batch: PyTree, labels: Sequence[Any] | None = None, dim: str = "scenario") -> None:
        sizes = {int(np.shape(x)[0]) for x in jax.tree.leaves(batch) if np.ndim(x) > 0}
        if len(sizes) != 1:
            raise ValueError(f"{type(self).__name__}: the scenarios need one leading axis, got sizes {sorted(sizes)}")
        self.batch = batch
        self.n = sizes.pop()
        self.labels = list(range(self.n)) if labels is None else list(labels)
        if len(self.labels) != self.n:
            raise ValueError(f"{type(self).__name__}: {len(self.labels)} labels for {self.n} scenarios")
        self.dim = dim

    def points(self) -> list[tuple]:
        """One empty tuple per scenario (no axes)."""
        return [() for _ in range(self.n)]

    def scenarios(self, build: Builder | None, points: list) -> PyTree:
        """The scenarios given (:meth:`AbstractSampler.scenarios`; no builder is needed).

        Args:
            build: Unused.
            points: Unused: every scenario is run.

        Returns:
            The batch given.
        """
        return self.batch

    def layout(self, axis_meta: AxisMeta) -> Layout:
        """The one dim, the labels as its coordinate (:meth:`AbstractSampler.layout`).

        Args:
            axis_meta: The dim's attributes (``units``, ``long_name``) by its name.

        Returns:
            (dims, shape, coordinates).
        """
        return (self.dim,), (self.n,), {self.dim: (self.dim, self.labels, axis_meta(self.dim))}


class Recordings(Given):
    """Recorded signals, laid out along the dim ``recording``.

    Args:
        signals: The recordings, batched (leading axis one per recording, e.g. :func:`jaxobs.signals.stack`
            of :class:`~jaxobs.SampledSignal` s).
        files: Their names (the ``recording`` coordinate).
        sha256: Their digests (the Dataset's ``recordings_sha256``).

    Raises:
        ValueError: No recordings, or as :class:`Given`.
    """

    sampling: ClassVar[str] = "recordings"
    dim_attrs: ClassVar[dict] = {"long_name": "recording file (relative to the study file)"}

    def __init__(self, signals: PyTree, files: Sequence[str], sha256: Sequence[str] = ()) -> None:
        self.files = tuple(map(str, files))
        self.sha256 = tuple(sha256)
        if not self.files:
            raise ValueError("Recordings needs at least one recording")
        super().__init__(signals, self.files, dim="recording")


# a study's ``sampling`` name -> its sampler over a dict of axes (the presets' and the study files' one table)
SAMPLINGS: dict[str, type] = {"grid": Grid, "random": Random, "sobol": Sobol, "lhs": LHS}


def sampler_of(
    axes: AbstractSampler | Mapping[str, Any], *, sampling: str | None = None, sample: int = 0, seed: int = 0
) -> AbstractSampler:
    """The sampler of a study: how the study preset (:func:`jaxobs.studies.study.run_study`) takes its
    scenarios.

    Args:
        axes: A sampler, taken as it is; or a dict of axis values: a :class:`Grid`, or ``sample`` points drawn
            by ``sampling``.
        sampling: ``"grid"``, ``"random"``, ``"sobol"`` or ``"lhs"`` (:data:`SAMPLINGS`); None: ``"random"``
            with ``sample`` > 0, else ``"grid"``.
        sample: The number of points drawn (0 with a grid).
        seed: The draws' seed.

    Returns:
        The sampler.

    Raises:
        ValueError: ``axes`` neither, an unknown ``sampling``, ``sample`` given with a grid or a sampler, or a
            value its sampler refuses (each naming the field).
    """
    if isinstance(axes, AbstractSampler):
        if sampling is not None or sample:
            raise ValueError("sampling and sample apply to a dict of axes; a sampler is taken as it is")
        return axes
    if not isinstance(axes, dict):
        raise ValueError(f"axes must be a dict of axis values or a sampler (jaxobs.scenarios), got {axes!r}")
    sampling = ("random" if sample else "grid") if sampling is None else sampling
    if sampling not in SAMPLINGS:
        raise ValueError(f"sampling must be 'grid', 'random', 'sobol' or 'lhs', got {sampling!r}")
    if sampling == "grid":  # the table's one sampler without a count
        if sample:
            raise ValueError("sample applies to sampling 'random', 'sobol' or 'lhs' (a grid runs every combination)")
        return Grid(axes)
    return SAMPLINGS[sampling](axes, sample, seed)

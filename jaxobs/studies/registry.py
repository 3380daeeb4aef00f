"""The one registry of observers: names and aliases to classes, with what jobs, studies and the export need.

Each :class:`Registered` entry names an observer class and adds only application facts: the signals and
machines a tuning job runs it on, a job's initial values and the short names of its closed form
(``"sogi-fll"``).  What belongs to the class is read from it: its gains and their units
(:func:`jaxobs.observers.gain_fields`), its closed form with its formulas and sources (``closed_form_design``),
whether a job may tune it (``why_not_tunable``) and which of :mod:`jaxobs.linear`'s small-signal models is its
paper's (``small_signal_model``, evaluated by :meth:`Registered.model` for ``jaxobs_tuning.structure``).
Every registered class has a closed form.  ``jaxobs_tuning.job.COMPONENTS`` is a view of it; the command line
(``closed-form``, ``export --design``), study files and the export read it.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable
from typing import Any

from .. import linear, papers
from ..drive import DualPMSMParams, PMSMParams
from ..observers import (
    CLESO,
    FALESO,
    GILESO,
    SOGIFLL,
    SOGIFLLWIF,
    SOGIFLLWPF,
    SOIFO,
    AbstractFluxObserver,
    LPFFlux,
    PureIntegratorFlux,
    ReducedOrderFluxObserver,
    SecondOrderSOIFO,
    gain_fields,
    rofo,
)

__all__ = ["Registered", "REGISTRY", "registered", "closed_form_gains", "canonical_key", "KEY_ALIASES"]


@dataclasses.dataclass(frozen=True)
class Registered:
    """An observer class and what the applications need beside it.

    Attributes:
        cls: the observer class.
        signal: the scenarios a tuning job runs it on by default: ``"grid"``, ``"emf"`` or ``"drive"``.
        machines: the shipped drive files (``jaxobs.drive.SHIPPED_DRIVES``) a drive job may name for it, the
            default first; empty: no drive jobs.  A drive file of the user's is checked by :meth:`refusal`.
        salient: whether it runs on a salient machine (Ld ≠ Lq).
        dual: whether it runs on a dual three-phase machine (its αβ subspace, :mod:`jaxobs.drive.dual`).
        why_not_salient: the one-line reason of a refusal on a salient machine.
        why_not_dual: the one-line reason of a refusal on a dual three-phase machine.
        defaults: a job's constructor values before its ``[component]`` and ``[gains]`` tables, at the class's
            default sample time.
        aliases: short names of the closed form (``jaxobs closed-form``, study files, ``export --design``).
        defaults_for_ts: where some defaults are a closed form that depends on the sample time (the reduced-order
            flux observer's matched-pole speed gains), the defaults at a given period T_s (s); None: ``defaults``
            hold at every period (:meth:`defaults_at`).
    """

    cls: type
    signal: str
    defaults: dict
    machines: tuple = ()
    salient: bool = True
    dual: bool = False
    why_not_salient: str = ""
    why_not_dual: str = ""
    aliases: tuple = ()
    defaults_for_ts: Callable[[float], dict] | None = None

    def defaults_at(self, ts: float | None) -> dict:
        """A job's constructor values before its tables, at the sample time the component will run at: a drive
        job's observer runs at its drive file's period, and a closed form designed at another period would put
        its poles elsewhere (the reduced-order flux observer's matched pole α' = (1 − e^{−α_o T_s})/T_s).

        Args:
            ts: The period, s (None: the class's default).

        Returns:
            name -> value (a new dict; ``ts`` itself is not among them).
        """
        if ts is None or self.defaults_for_ts is None:
            return dict(self.defaults)
        return self.defaults_for_ts(float(ts))

    @property
    def name(self) -> str:
        """The class's name."""
        return self.cls.__name__

    @property
    def tunable(self) -> bool:
        """Whether a tuning job may name it: the class declares why not (``why_not_tunable``) where it may not."""
        return not self.cls.why_not_tunable

    @property
    def closed_form_source(self) -> str:
        """The paper's equations and table of the class's closed form, in one line (its ``ClosedForm.source``)."""
        return self.cls.closed_form_design().source

    @property
    def closed_form_rule(self) -> str:
        """The closed form's source and formulas, in one line (its ``ClosedForm.rule``: the export's source line)."""
        return self.cls.closed_form_design().rule

    @property
    def model(self) -> Callable[[dict], Any] | None:
        """The paper's small-signal model at a design's constructor values (name -> value), or None where the
        papers give none: the :mod:`jaxobs.linear` function the class names in ``small_signal_model``, called
        with the fields it lists (``jaxobs_tuning.structure``)."""
        if self.cls.small_signal_model is None:
            return None
        return functools.partial(_model_at, self.cls.small_signal_model)

    @property
    def gains(self) -> tuple:
        """The gains a job may tune: the class's gain fields (:func:`jaxobs.observers.gain_fields`)."""
        return tuple(gain_fields(self.cls))

    def refusal(self, machine: PMSMParams | DualPMSMParams) -> str | None:
        """Why this component cannot run on ``machine``.

        Args:
            machine: A :class:`~jaxobs.drive.PMSMParams` or a dual machine's :class:`~jaxobs.drive.DualPMSMParams`.

        Returns:
            The reason, in one line; None where it can run.
        """
        if not self.machines:
            return f"{self.name} runs on no drive (it is not a drive observer)"
        is_dual = isinstance(machine, DualPMSMParams)
        if is_dual and not self.dual:
            return f"{self.name} does not run on a dual three-phase machine: {self.why_not_dual}"
        m = machine.per_set() if is_dual else machine
        ld, lq = float(m.Ld), float(m.Lq)
        if abs(lq - ld) > 1e-9 * max(ld, lq) and not self.salient:
            why = self.why_not_salient
            return f"{self.name} does not run on a salient machine (Ld = {ld:.4g} H, Lq = {lq:.4g} H): {why}"
        return None

    @property
    def signals(self) -> tuple:
        """The scenario signals this component runs on, its default first."""
        return (self.signal, "drive") if self.machines and self.signal != "drive" else (self.signal,)


# Keys that name a field by another name on input: job files' [component] tables and result.json's values may
# name a flux observer's initial speed ``omega0`` (its field is ``omega_init``: a LESO's ω0 is its bandwidth).
KEY_ALIASES = {"omega0": "omega_init"}


def canonical_key(cls, key: str) -> str:
    """The field a key names for ``cls``.

    Args:
        cls: The observer class.
        key: The key (of a job file's ``[component]`` table or a result's values).

    Returns:
        For a flux observer, the field a key of :data:`KEY_ALIASES` maps to; any other key itself.
    """
    return KEY_ALIASES.get(key, key) if issubclass(cls, AbstractFluxObserver) else key


W_N = papers.FLL_OMEGA_N
# A LESO's extended-EMF model (002 eqs 4–5) holds on a non-salient machine too (Ld = Lq), so the LESOs
# may run on 000's SPMSM.  The flux observers run on a salient machine through the active flux
# ψa = ψf + (Ld − Lq) i_d (jaxobs.observers.flux, "Salient machines": bound to a machine they take L̂q): their
# filters and FLL/PLL normalizations do not depend on the flux amplitude, so 000's closed forms hold at every
# steady point; what is new is that |ψa| moves with i_d (under MTPA it falls with the load, and an i_d step is
# an amplitude step the filters pass with a transient), which 000's analysis and docs/stability.md, at constant
# amplitude, do not cover.  Their drive jobs still default to 000's SPMSM and may name 002's IPMSM.
_LESO_MACHINES = ("ipmsm002", "spmsm000")
_FLUX_MACHINES = ("spmsm000", "ipmsm002")  # 000's SPMSM first: their drive jobs' default machine
_FLUX_SUPPORT: dict[str, Any] = dict(
    salient=True,
    why_not_dual="000's observers are derived and checked on a three-phase machine only",
)
# 002's LESOs run on either: they are 002's observers of a dual three-phase IPMSM (its αβ subspace,
# jaxobs.reproduce.leso_dual) and their extended EMF holds with Ld ≠ Lq (002 eqs 4–5)
_LESO_SUPPORT: dict[str, Any] = dict(salient=True, dual=True)


def _pll(hz) -> dict:
    kp, ki = linear.pll_gains(2 * math.pi * hz)
    return {"kp_pll": float(kp), "ki_pll": float(ki)}


def _leso_defaults(**gains):
    return dict(Rs=papers.IPMSM_002["Rs"], Lq=papers.IPMSM_002["Lq"], **gains, **_pll(papers.LESO_PLL_HZ))


def _rofo_defaults(ts: float = 1e-4) -> dict:
    # the closed form (ReducedOrderFluxObserver.closed_form) at the period ts (default: the class's), in Python
    # floats; the machine's values are placeholders a drive job binds (002's IPMSM, the entry's default machine)
    # (matched_pole in plain floats: importing the registry runs no JAX computation, which would start JAX before
    # the command line sets its device count)
    am = rofo.matched_pole(2 * math.pi * rofo.ROFO_ALPHA_O_HZ, ts)
    k_theta, k_omega = 2.0 * am, am * am
    machine = {k: papers.IPMSM_002[k] for k in ("Rs", "Ld", "Lq", "psi_f")}
    gains = dict(c_sigma=rofo.ROFO_C_SIGMA, zeta_inf=rofo.ROFO_ZETA_INF, k_theta=k_theta, k_omega=k_omega)
    return {**machine, **gains}


_ENTRIES = (
    Registered(
        SOGIFLL,
        signal="grid",
        defaults=dict(k=papers.SOGI_FLL_K, lam=papers.SOGI_FLL_LAM, omega_n=W_N),
        aliases=("sogi-fll",),
    ),
    Registered(
        SOGIFLLWPF,
        signal="grid",
        defaults=dict(k1=papers.WPF_K1, k2=papers.WPF_K2, lam=papers.WPF_LAM, omega_n=W_N),
        aliases=("wpf",),
    ),
    Registered(
        SOGIFLLWIF,
        signal="grid",
        defaults=dict(k1=papers.WIF_K1, k2=papers.WIF_K2, lam=papers.WIF_LAM, omega_n=W_N),
        aliases=("wif",),
    ),
    Registered(
        SOIFO,
        signal="emf",
        defaults=dict(Rs=0.0, L=1.0, k=papers.SOIFO_K, lam=0.5, omega_init=W_N),
        aliases=("soifo",),
        machines=_FLUX_MACHINES,
        **_FLUX_SUPPORT,
    ),
    Registered(
        SecondOrderSOIFO,
        signal="emf",
        defaults=dict(
            Rs=0.0,
            L=1.0,
            K1=papers.SECOND_ORDER_SOIFO_K1,
            K2=papers.SECOND_ORDER_SOIFO_K2,
            lam=linear.second_order_soifo_lambda(papers.SECOND_ORDER_SOIFO_K1, papers.SECOND_ORDER_SOIFO_K2),
            omega_init=W_N,
        ),
        aliases=("second-order-soifo",),
        machines=_FLUX_MACHINES,
        **_FLUX_SUPPORT,
    ),
    # 000's LPF flux estimator ψ̂ = ê/(s + ωc), uncompensated as in 000 Fig. 5, with the type-2 PLL (ASSUMED,
    # papers.FLUX_PLL_HZ) that gives it a speed: drive jobs only (on a bare EMF signal its PLL has nothing
    # to close).  No small-signal model of its PLL through the filter is in jaxobs.linear.
    Registered(
        LPFFlux,
        signal="drive",
        defaults=dict(
            Rs=papers.SPMSM_000["Rs"], L=papers.SPMSM_000["Ld"], omega_c=papers.LPF_OMEGA_C, **_pll(papers.FLUX_PLL_HZ)
        ),
        aliases=("lpf",),
        machines=_FLUX_MACHINES,
        **_FLUX_SUPPORT,
    ),
    # The pure integrator is no job component (its class says why: PureIntegratorFlux.why_not_tunable).
    # Studies may still name it.
    Registered(
        PureIntegratorFlux,
        signal="drive",
        defaults=dict(Rs=papers.SPMSM_000["Rs"], L=papers.SPMSM_000["Ld"]),
        aliases=("integrator",),
        machines=_FLUX_MACHINES,
        **_FLUX_SUPPORT,
    ),
    Registered(
        CLESO,
        signal="drive",
        defaults=_leso_defaults(omega0=papers.LESO_OMEGA0),
        machines=_LESO_MACHINES,
        **_LESO_SUPPORT,
        aliases=("cleso",),
    ),
    Registered(
        GILESO,
        signal="drive",
        defaults=_leso_defaults(omega0=papers.LESO_OMEGA0, K_r=papers.GILESO_K_R, omega_c=papers.GILESO_OMEGA_C),
        aliases=("gileso",),
        machines=_LESO_MACHINES,
        **_LESO_SUPPORT,
    ),
    Registered(
        FALESO,
        signal="drive",
        defaults=_leso_defaults(k1=papers.FALESO_K1, k2=papers.FALESO_K2),
        aliases=("faleso",),
        machines=_LESO_MACHINES,
        **_LESO_SUPPORT,
    ),
    # The reduced-order flux observer of Hinkkanen et al. 2018 (jaxobs.observers.rofo): a stator-flux observer in
    # estimated rotor coordinates with both inductances, so it runs on salient and non-salient machines.  Its
    # gains are dimensionless or in rad/s (c_sigma scales with the bound machine's Rs/L), so one design holds on
    # any machine; the defaults are its closed form at the default ts.  No small-signal model of it is in
    # jaxobs.linear (its linearised poles are in the module doc).  Dual three-phase: not derived here.
    Registered(
        ReducedOrderFluxObserver,
        signal="drive",
        defaults=_rofo_defaults(),
        defaults_for_ts=_rofo_defaults,  # its speed gains are the matched pole at the period it runs at
        machines=_LESO_MACHINES,
        salient=True,
        dual=False,
        why_not_dual="its error dynamics are derived for a three-phase machine only",
        aliases=("rofo",),
    ),
)

REGISTRY: dict[str, Registered] = {e.name: e for e in _ENTRIES}
_BY_ALIAS = {a: e for e in _ENTRIES for a in e.aliases}


def registered(name: str) -> Registered:
    """The entry of a class name (``"SOGIFLLWIF"``) or an alias (``"wif"``).

    Args:
        name: The class name or alias.

    Returns:
        The :class:`Registered` entry.

    Raises:
        ValueError: an unknown name, with the known ones.
    """
    entry = REGISTRY.get(name) or _BY_ALIAS.get(name)
    if entry is None:
        raise ValueError(f"unknown observer {name!r}; known: {', '.join([*REGISTRY, *_BY_ALIAS])}")
    return entry


def spelled(name: str) -> str:
    """A design named on the command line as the registry spells it: a class name (``SOGIFLLWIF``) or an alias
    (``wif``), in any case, read as the entry's first alias; any other name as given (for the caller's error).

    Args:
        name: The name typed.

    Returns:
        The alias, or ``name``.
    """
    low = name.lower()
    for e in _ENTRIES:
        if low == e.name.lower() or low in (a.lower() for a in e.aliases):
            return low if low in e.aliases else e.aliases[0]
    return name


def _model_at(spec: tuple, values: dict):
    """The small-signal model a class names (``(function of jaxobs.linear, its fields)``) at ``values``."""
    fn, fields = spec
    return getattr(linear, fn)(*(float(values[f]) for f in fields))


def closed_form_gains(name: str, component: Any = None) -> dict[str, float]:
    """A registered class's closed-form gains as floats (name -> value), at ``component``'s nominal frequency
    ``omega_n`` where it has one (the FLLs) and at its sample time (the reduced-order flux observer's matched
    pole depends on it); the gains of :meth:`Registered.gains`.

    Args:
        name: a class name or alias.
        component: an instance whose ``omega_n`` and ``ts`` the closed form takes, or None (the paper's, at the
            class's default ts).

    Returns:
        gain name -> float.
    """
    entry = registered(name)
    takes_omega_n = "omega_n" in entry.cls.closed_form_design().inputs
    kw = {"omega_n": float(component.omega_n)} if component is not None and takes_omega_n else {}
    if component is not None:  # every closed form takes the constructor's ts (the period it is designed at)
        kw["ts"] = float(component.ts)
    obs = entry.cls.closed_form(**kw)
    return {g: float(getattr(obs, g)) for g in entry.gains}

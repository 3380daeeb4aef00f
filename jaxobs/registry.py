"""The one registry of observers: names and aliases to classes, with what jobs, studies and the export need.

Each :class:`Registered` entry names an observer class (its gains and their units are the class's own,
:func:`jaxobs.observers.gain_fields`; its closed form is the class's ``closed_form``) and adds what is not a
property of the class: the signals and machines a tuning job runs it on, a job's initial values, the
short names of its closed form (``"sogi-fll"``), and the paper's small-signal model that
``jaxobs_tuning.structure`` evaluates.  ``jaxobs_tuning.job.COMPONENTS`` is a view of it; the command line
(``closed-form``, ``export --design``), study files and the export read it.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
from collections.abc import Callable
from typing import Any

from . import linear, papers
from .drive import DualPMSMParams
from .observers import (
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
    SecondOrderSOIFO,
    gain_fields,
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
        defaults: a job's constructor values before its ``[component]`` and ``[gains]`` tables.
        closed_form_source: the paper's equations and table of the closed form, in one line.
        closed_form_rule: the closed form's formulas, in one line (the export's source line).
        aliases: short names of the closed form (``jaxobs closed-form``, study files, ``export --design``).
        tunable: whether a tuning job may name it.
        model: the paper's small-signal model at a design's constructor values, or None where the papers give
            none (``jaxobs_tuning.structure``).
    """

    cls: type
    signal: str
    defaults: dict
    closed_form_source: str = ""
    closed_form_rule: str = ""
    machines: tuple = ()
    salient: bool = True
    dual: bool = False
    why_not_salient: str = ""
    why_not_dual: str = ""
    aliases: tuple = ()
    tunable: bool = True
    model: Callable[[dict], Any] | None = None

    @property
    def name(self) -> str:
        return self.cls.__name__

    @property
    def gains(self) -> tuple:
        """The gains a job may tune: the class's gain fields (:func:`jaxobs.observers.gain_fields`)."""
        return tuple(gain_fields(self.cls))

    def refusal(self, machine) -> str | None:
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
_FLUX_SUPPORT = dict(
    salient=True,
    why_not_dual="000's observers are derived and checked on a three-phase machine only",
)
# 002's LESOs run on either: they are 002's observers of a dual three-phase IPMSM (its αβ subspace,
# jaxobs.reproduce.leso_dual) and their extended EMF holds with Ld ≠ Lq (002 eqs 4–5)
_LESO_SUPPORT = dict(salient=True, dual=True)


def _pll(hz) -> dict:
    kp, ki = linear.pll_gains(2 * math.pi * hz)
    return {"kp_pll": float(kp), "ki_pll": float(ki)}


def _leso_defaults(**gains):
    return dict(Rs=papers.IPMSM_002["Rs"], Lq=papers.IPMSM_002["Lq"], **gains, **_pll(papers.LESO_PLL_HZ))


_ENTRIES = (
    Registered(
        SOGIFLL,
        signal="grid",
        defaults=dict(k=papers.SOGI_FLL_K, lam=papers.SOGI_FLL_LAM, omega_n=W_N),
        closed_form_source="001 eq (22), Table I",
        closed_form_rule="001 eq (22): k = 1/√2, λ = k²ωn²/(8ζ²), ζ = 1/√2",
        aliases=("sogi-fll",),
        model=lambda v: linear.sogi_fll_model(float(v["k"]), float(v["lam"]), float(v["omega_n"])),
    ),
    Registered(
        SOGIFLLWPF,
        signal="grid",
        defaults=dict(k1=papers.WPF_K1, k2=papers.WPF_K2, lam=papers.WPF_LAM, omega_n=W_N),
        closed_form_source="001 eq (29), Table I",
        closed_form_rule="001 eq (29): k1 = k2 = √2, λ = 2(ζ+1)ωn²/(2ζ+1)³, ζ = 1/√2",
        aliases=("wpf",),
        model=lambda v: linear.wpf_model(float(v["k1"]), float(v["k2"]), float(v["lam"]), float(v["omega_n"])),
    ),
    Registered(
        SOGIFLLWIF,
        signal="grid",
        defaults=dict(k1=papers.WIF_K1, k2=papers.WIF_K2, lam=papers.WIF_LAM, omega_n=W_N),
        closed_form_source="001 eq (34), Table I",
        closed_form_rule="001 eq (34), symmetric optimum: b = 1+√2, ωc = 2π·18.8 rad/s",
        aliases=("wif",),
        model=lambda v: linear.wif_model(float(v["k1"]), float(v["k2"]), float(v["lam"]), float(v["omega_n"])),
    ),
    Registered(
        SOIFO,
        signal="emf",
        defaults=dict(Rs=0.0, L=1.0, k=papers.SOIFO_K, lam=0.5, omega_init=W_N),
        closed_form_source="000 (k = 1.414), lam = k²/4",
        closed_form_rule="000: k = 1.414; lam = k²/4 (001 eq 22, frequency-normalized)",
        machines=_FLUX_MACHINES,
        **_FLUX_SUPPORT,
        model=lambda v: linear.soifo_tf(float(v["k"]), float(v["omega_init"])),
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
        closed_form_source="000 (K1 = 1.56, K2 = 3.11), lam = K1³/(2K2)",
        closed_form_rule="000: K1 = 1.56, K2 = 3.11; lam = K1³/(2K2) (001 eq 34, frequency-normalized)",
        machines=_FLUX_MACHINES,
        **_FLUX_SUPPORT,
        model=lambda v: linear.sosoifo_tf(float(v["K1"]), float(v["K2"]), float(v["omega_init"])),
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
        closed_form_source="000 Fig. 5 (omega_c = 100 rad/s), PLL pole placement omega_b = 2 pi 20 (ASSUMED)",
        closed_form_rule="000 Fig. 5: omega_c = 100 rad/s; PLL kp = 2ζω_b, ki = ω_b², ω_b = 2π·20 (ASSUMED)",
        machines=_FLUX_MACHINES,
        **_FLUX_SUPPORT,
    ),
    # The pure integrator is no job component: its flux starts from zero, so its circle is offset by the flux
    # at its start (000's "unknown integral initial value") and θ̂ is wrong by up to 90° whatever its PLL
    # gains; in a sensorless drive it loses synchronism.  Studies may still name it.
    Registered(
        PureIntegratorFlux,
        signal="drive",
        defaults=dict(Rs=papers.SPMSM_000["Rs"], L=papers.SPMSM_000["Ld"]),
        machines=_FLUX_MACHINES,
        **_FLUX_SUPPORT,
        tunable=False,
    ),
    Registered(
        CLESO,
        signal="drive",
        defaults=_leso_defaults(omega0=papers.LESO_OMEGA0),
        closed_form_source="002 Table II (ω0 = 500π), PLL pole placement ω_b = 2π·15",
        closed_form_rule="002 eq (16), Table II: l1 = 2ω0 − μ, l2 = ω0², ω0 = 500π; PLL ω_b = 2π·15",
        machines=_LESO_MACHINES,
        **_LESO_SUPPORT,
        aliases=("cleso",),
    ),
    Registered(
        GILESO,
        signal="drive",
        defaults=_leso_defaults(omega0=papers.LESO_OMEGA0, K_r=papers.GILESO_K_R, omega_c=papers.GILESO_OMEGA_C),
        closed_form_source="002 Table II (ω0 = 500π, K_r = 2ω0², ωc = π), PLL pole placement ω_b = 2π·15",
        closed_form_rule="002 Table II: ω0 = 500π, K_r = 2ω0², ωc = π; PLL ω_b = 2π·15",
        machines=_LESO_MACHINES,
        **_LESO_SUPPORT,
    ),
    Registered(
        FALESO,
        signal="drive",
        defaults=_leso_defaults(k1=papers.FALESO_K1, k2=papers.FALESO_K2),
        closed_form_source="002 Table II (k1 = 10π, k2 = 100π), PLL pole placement ω_b = 2π·15",
        closed_form_rule="002 Table II: k1 = 10π, k2 = 100π; PLL ω_b = 2π·15",
        machines=_LESO_MACHINES,
        **_LESO_SUPPORT,
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


def closed_form_gains(name: str, component=None) -> dict:
    """A registered class's closed-form gains as floats (name -> value), at ``component``'s nominal frequency
    ``omega_n`` where it has one (the FLLs); the gains of :meth:`Registered.gains`.

    Args:
        name: a class name or alias.
        component: an instance whose ``omega_n`` the closed form takes, or None (the paper's).

    Returns:
        gain name -> float.
    """
    entry = registered(name)
    takes_omega_n = "omega_n" in inspect.signature(entry.cls.closed_form).parameters
    kw = {"omega_n": float(component.omega_n)} if component is not None and takes_omega_n else {}
    obs = entry.cls.closed_form(**kw)
    return {g: float(getattr(obs, g)) for g in entry.gains}

"""The tunable components: constructor, free gains, defaults, closed form and its source, signals, machines."""

from __future__ import annotations

import math
from dataclasses import dataclass

import jaxobs
from jaxobs import linear, papers
from jaxobs.drive_study import bind_observer

W_N = papers.FLL_OMEGA_N


SOIFO_K, SOIFO2_K1, SOIFO2_K2 = papers.SOIFO_K, papers.SECOND_ORDER_SOIFO_K1, papers.SECOND_ORDER_SOIFO_K2


def _cf_sogi(comp):
    k = papers.SOGI_FLL_K
    return {"k": k, "lam": float(linear.sogi_fll_lambda(k, float(comp.omega_n)))}


def _cf_wpf(comp):
    return {"k1": papers.WPF_K1, "k2": papers.WPF_K2, "lam": float(linear.wpf_lambda(float(comp.omega_n)))}


def _cf_wif(comp):
    k1, k2, lam = linear.wif_symmetric_optimum(papers.WIF_B, papers.WIF_OMEGA_C, float(comp.omega_n))
    return {"k1": float(k1), "k2": float(k2), "lam": float(lam)}


def _cf_soifo(comp):
    return {"k": SOIFO_K, "lam": linear.soifo_lambda(SOIFO_K)}


def _cf_sosoifo(comp):
    return {"K1": SOIFO2_K1, "K2": SOIFO2_K2, "lam": linear.second_order_soifo_lambda(SOIFO2_K1, SOIFO2_K2)}


def _cf_lpf(comp):
    return {"omega_c": papers.LPF_OMEGA_C, **_flux_pll_cf()}


def _flux_pll_cf():
    kp, ki = linear.pll_gains(2 * math.pi * papers.FLUX_PLL_HZ)
    return {"kp_pll": float(kp), "ki_pll": float(ki)}


def _cf_cleso(comp):
    return {"omega0": papers.LESO_OMEGA0}


def _pll_cf():
    kp, ki = linear.pll_gains(2 * math.pi * papers.LESO_PLL_HZ)
    return {"kp_pll": float(kp), "ki_pll": float(ki)}


def _cf_faleso(comp):
    return {"k1": papers.FALESO_K1, "k2": papers.FALESO_K2, **_pll_cf()}


@dataclass(frozen=True)
class ComponentInfo:
    ctor: object
    gains: tuple
    defaults: dict
    closed_form: object
    signal: str
    closed_form_source: str
    bind: object = None
    # the machines a sensorless drive job may run this component on, the default first (BENCH_MACHINES);
    # empty: no drive jobs.  A component whose ``signal`` is "emf" runs on EMF signals by default and in the
    # drive with ``scenarios.signal = "drive"``.
    machines: tuple = ()

    @property
    def signals(self) -> tuple:
        """The scenario signals this component runs on, its default first."""
        return tuple(dict.fromkeys((self.signal, "drive"))) if self.machines else (self.signal,)


# A LESO's extended-EMF model (002 eqs 4–5) holds on a non-salient machine too (Ld = Lq), so the LESOs
# may run on 000's SPMSM; the flux observers may not run on the IPMSM: their back EMF u − R̂s i − L̂ di/dt
# with one inductance is not dψ_f/dt on a salient machine.
_LESO_MACHINES = ("ipmsm002", "spmsm000")


COMPONENTS = {
    "SOGIFLL": ComponentInfo(
        jaxobs.SOGIFLL,
        gains=("k", "lam"),
        defaults=dict(k=papers.SOGI_FLL_K, lam=papers.SOGI_FLL_LAM, omega_n=W_N),
        closed_form=_cf_sogi,
        signal="grid",
        closed_form_source="001 eq (22), Table I",
    ),
    "SOGIFLLWPF": ComponentInfo(
        jaxobs.SOGIFLLWPF,
        gains=("k1", "k2", "lam"),
        defaults=dict(k1=papers.WPF_K1, k2=papers.WPF_K2, lam=papers.WPF_LAM, omega_n=W_N),
        closed_form=_cf_wpf,
        signal="grid",
        closed_form_source="001 eq (29), Table I",
    ),
    "SOGIFLLWIF": ComponentInfo(
        jaxobs.SOGIFLLWIF,
        gains=("k1", "k2", "lam"),
        defaults=dict(k1=papers.WIF_K1, k2=papers.WIF_K2, lam=papers.WIF_LAM, omega_n=W_N),
        closed_form=_cf_wif,
        signal="grid",
        closed_form_source="001 eq (34), Table I",
    ),
    "SOIFO": ComponentInfo(
        jaxobs.SOIFO,
        gains=("k", "lam"),
        defaults=dict(Rs=0.0, L=1.0, k=SOIFO_K, lam=0.5, omega0=W_N),
        closed_form=_cf_soifo,
        signal="emf",
        closed_form_source="000 (k = 1.414), lam = k²/4",
        machines=("spmsm000",),
    ),
    "SecondOrderSOIFO": ComponentInfo(
        jaxobs.SecondOrderSOIFO,
        gains=("K1", "K2", "lam"),
        defaults=dict(
            Rs=0.0,
            L=1.0,
            K1=SOIFO2_K1,
            K2=SOIFO2_K2,
            lam=linear.second_order_soifo_lambda(SOIFO2_K1, SOIFO2_K2),
            omega0=W_N,
        ),
        closed_form=_cf_sosoifo,
        signal="emf",
        closed_form_source="000 (K1 = 1.56, K2 = 3.11), lam = K1³/(2K2)",
        machines=("spmsm000",),
    ),
    # 000's LPF flux estimator ψ̂ = ê/(s + ωc), uncompensated as in 000 Fig. 5, with the type-2 PLL (ASSUMED,
    # papers.FLUX_PLL_HZ) that gives it a speed: drive jobs only (on a bare EMF signal its PLL has nothing
    # to close).  The pure integrator is no job component: its flux starts from zero, so its circle is
    # offset by the flux at its start (000's "unknown integral initial value") and θ̂ is wrong by up to
    # 90° whatever its PLL gains; in a sensorless drive it loses synchronism (README, "Drive jobs").
    "LPFFlux": ComponentInfo(
        jaxobs.LPFFlux,
        gains=("omega_c", "kp_pll", "ki_pll"),
        defaults=dict(
            Rs=papers.SPMSM_000["Rs"], L=papers.SPMSM_000["Ld"], omega_c=papers.LPF_OMEGA_C, **_flux_pll_cf()
        ),
        closed_form=_cf_lpf,
        signal="drive",
        closed_form_source="000 Fig. 5 (omega_c = 100 rad/s), PLL pole placement omega_b = 2 pi 20 (ASSUMED)",
        bind=bind_observer,  # the scenario's assumed Rs, L; the PLL starts at its speed
        machines=("spmsm000",),
    ),
    # the drive jobs run the ASSUMED IPMSM of jaxobs.papers; a LESO starts from its Rs and Lq
    "CLESO": ComponentInfo(
        jaxobs.CLESO,
        gains=("omega0", "kp_pll", "ki_pll"),
        defaults=dict(Rs=papers.IPMSM_002["Rs"], Lq=papers.IPMSM_002["Lq"], omega0=papers.LESO_OMEGA0, **_pll_cf()),
        closed_form=lambda c: {**_cf_cleso(c), **_pll_cf()},
        signal="drive",
        closed_form_source="002 Table II (ω0 = 500π), PLL pole placement ω_b = 2π·15",
        bind=bind_observer,  # the scenario's assumed Rs, Lq; the PLL starts at its speed
        machines=_LESO_MACHINES,
    ),
    "GILESO": ComponentInfo(
        jaxobs.GILESO,
        gains=("omega0", "K_r", "omega_c", "kp_pll", "ki_pll"),
        defaults=dict(
            Rs=papers.IPMSM_002["Rs"],
            Lq=papers.IPMSM_002["Lq"],
            omega0=papers.LESO_OMEGA0,
            K_r=papers.GILESO_K_R,
            omega_c=papers.GILESO_OMEGA_C,
            **_pll_cf(),
        ),
        closed_form=lambda c: {
            "omega0": papers.LESO_OMEGA0,
            "K_r": papers.GILESO_K_R,
            "omega_c": papers.GILESO_OMEGA_C,
            **_pll_cf(),
        },
        signal="drive",
        closed_form_source="002 Table II (ω0 = 500π, K_r = 2ω0², ωc = π), PLL pole placement ω_b = 2π·15",
        bind=bind_observer,  # the scenario's assumed Rs, Lq; the PLL starts at its speed
        machines=_LESO_MACHINES,
    ),
    "FALESO": ComponentInfo(
        jaxobs.FALESO,
        gains=("k1", "k2", "kp_pll", "ki_pll"),
        defaults=dict(
            Rs=papers.IPMSM_002["Rs"], Lq=papers.IPMSM_002["Lq"], k1=papers.FALESO_K1, k2=papers.FALESO_K2, **_pll_cf()
        ),
        closed_form=_cf_faleso,
        signal="drive",
        closed_form_source="002 Table II (k1 = 10π, k2 = 100π), PLL pole placement ω_b = 2π·15",
        bind=bind_observer,  # the scenario's assumed Rs, Lq; the PLL starts at its speed
        machines=_LESO_MACHINES,
    ),
}

"""Linear analysis: transfer functions (real and complex coefficients), frequency
responses, margins, poles, the generalized Routh test, Tustin discretization, the
papers' small-signal models and closed-form tuning rules.

All functions are JAX functions of the coefficients: differentiable w.r.t. gains.
"""

from ._fll import (
    FLLModel as FLLModel,
    pll_gains as pll_gains,
    sogi_fll_closed_form as sogi_fll_closed_form,
    sogi_fll_lambda as sogi_fll_lambda,
    sogi_fll_model as sogi_fll_model,
    symmetric_optimum_pm as symmetric_optimum_pm,
    wif_closed_form as wif_closed_form,
    wif_model as wif_model,
    wif_symmetric_optimum as wif_symmetric_optimum,
    wpf_closed_form as wpf_closed_form,
    wpf_lambda as wpf_lambda,
    wpf_model as wpf_model,
)
from ._models import (
    CLESOGains as CLESOGains,
    cleso_closed_form as cleso_closed_form,
    cleso_tf as cleso_tf,
    faleso_is_stable as faleso_is_stable,
    faleso_pll_loop as faleso_pll_loop,
    faleso_tf as faleso_tf,
    flux_dc_gain as flux_dc_gain,
    gileso_tf as gileso_tf,
    integrator_flux_tf as integrator_flux_tf,
    leso_tf as leso_tf,
    lpf_compensation as lpf_compensation,
    lpf_flux_tf as lpf_flux_tf,
    position_error_lq as position_error_lq,
    position_error_rs as position_error_rs,
    sogi2_tf as sogi2_tf,
    sogi2_tustin_paper as sogi2_tustin_paper,
    soifo_harmonic_factor as soifo_harmonic_factor,
    soifo_tf as soifo_tf,
    sosoifo_harmonic_factor as sosoifo_harmonic_factor,
    sosoifo_tf as sosoifo_tf,
)
from ._tf import (
    DiscreteTransferFunction as DiscreteTransferFunction,
    Margins as Margins,
    TransferFunction as TransferFunction,
    bode as bode,
    is_hurwitz as is_hurwitz,
    margins as margins,
    routh_complex as routh_complex,
    tustin as tustin,
)

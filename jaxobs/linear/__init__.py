"""Linear analysis: transfer functions (real and complex coefficients), frequency
responses, margins, poles, the generalized Routh test, Tustin discretization, the
papers' small-signal models and closed-form tuning rules.

All functions are JAX functions of the coefficients: differentiable w.r.t. gains.
"""

from ._discrete import DiscreteTransferFunction as DiscreteTransferFunction
from ._discrete import tustin as tustin
from ._fll import (
    FLLModel as FLLModel,
)
from ._fll import (
    pll_gains as pll_gains,
)
from ._fll import (
    second_order_soifo_lambda as second_order_soifo_lambda,
)
from ._fll import (
    sogi_fll_closed_form as sogi_fll_closed_form,
)
from ._fll import (
    sogi_fll_lambda as sogi_fll_lambda,
)
from ._fll import (
    sogi_fll_model as sogi_fll_model,
)
from ._fll import (
    soifo_lambda as soifo_lambda,
)
from ._fll import (
    symmetric_optimum_pm as symmetric_optimum_pm,
)
from ._fll import (
    wif_closed_form as wif_closed_form,
)
from ._fll import (
    wif_model as wif_model,
)
from ._fll import (
    wif_symmetric_optimum as wif_symmetric_optimum,
)
from ._fll import (
    wpf_closed_form as wpf_closed_form,
)
from ._fll import (
    wpf_lambda as wpf_lambda,
)
from ._fll import (
    wpf_model as wpf_model,
)
from ._margins import Margins as Margins
from ._margins import bode as bode
from ._margins import margins as margins
from ._models import (
    CLESOGains as CLESOGains,
)
from ._models import (
    cleso_closed_form as cleso_closed_form,
)
from ._models import (
    cleso_tf as cleso_tf,
)
from ._models import (
    faleso_is_stable as faleso_is_stable,
)
from ._models import (
    faleso_pll_loop as faleso_pll_loop,
)
from ._models import (
    faleso_speed_loop_poles as faleso_speed_loop_poles,
)
from ._models import (
    faleso_tf as faleso_tf,
)
from ._models import (
    flux_dc_gain as flux_dc_gain,
)
from ._models import (
    gileso_tf as gileso_tf,
)
from ._models import (
    integrator_flux_tf as integrator_flux_tf,
)
from ._models import (
    leso_tf as leso_tf,
)
from ._models import (
    lpf_compensation as lpf_compensation,
)
from ._models import (
    lpf_flux_tf as lpf_flux_tf,
)
from ._models import (
    position_error_lq as position_error_lq,
)
from ._models import (
    position_error_rs as position_error_rs,
)
from ._models import (
    sogi2_tf as sogi2_tf,
)
from ._models import (
    sogi2_tustin_paper as sogi2_tustin_paper,
)
from ._models import (
    soifo_harmonic_factor as soifo_harmonic_factor,
)
from ._models import (
    soifo_harmonic_phase as soifo_harmonic_phase,
)
from ._models import (
    soifo_tf as soifo_tf,
)
from ._models import (
    sosoifo_harmonic_factor as sosoifo_harmonic_factor,
)
from ._models import (
    sosoifo_harmonic_phase as sosoifo_harmonic_phase,
)
from ._models import (
    sosoifo_tf as sosoifo_tf,
)
from ._tf import TransferFunction as TransferFunction
from ._tf import is_hurwitz as is_hurwitz
from ._tf import routh_complex as routh_complex

"""jaxobs.linear <-> python-control: real transfer functions convert both ways and give
python-control's own frequency response and poles; complex ones are refused with one line; bode can
return python-control's conventions.  float64 (conftest)."""

import math

import control
import numpy as np
import pytest

import jaxobs.linear as L
from jaxobs import papers


def test_continuous_round_trip_and_frequency_response():
    tf = L.sosoifo_tf(papers.SECOND_ORDER_SOIFO_K1, papers.SECOND_ORDER_SOIFO_K2, 100 * math.pi)
    sys = tf.to_control()
    assert isinstance(sys, control.TransferFunction) and sys.dt == 0
    w = np.logspace(0, 4, 50)
    ours = np.asarray(tf.freqresp(w))
    theirs = sys(1j * w)
    np.testing.assert_allclose(ours, theirs, rtol=1e-12)
    np.testing.assert_allclose(np.sort_complex(np.asarray(tf.poles())), np.sort_complex(sys.poles()), rtol=1e-9)
    back = L.TransferFunction.from_control(sys)
    np.testing.assert_allclose(np.asarray(back.freqresp(w)), ours, rtol=1e-12)
    # bode in python-control's conventions: (|G|, phase rad, omega), as control.frequency_response gives
    mag, phase, omega = L.bode(tf, w, convention="control")
    fr = control.frequency_response(sys, w)
    np.testing.assert_allclose(np.asarray(mag), fr.magnitude, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(phase), np.unwrap(fr.phase), atol=1e-12)
    np.testing.assert_allclose(np.asarray(omega), w)
    db, deg = L.bode(tf, w)  # the default: dB and degrees
    np.testing.assert_allclose(np.asarray(db), 20 * np.log10(fr.magnitude), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(deg), np.degrees(np.asarray(phase)), rtol=1e-12)


def test_discrete_to_control():
    d = L.tustin(L.soifo_tf(math.sqrt(2), 100 * math.pi), 1e-4)
    sys = d.to_control()
    assert sys.dt == 1e-4
    w = np.linspace(10.0, 3000.0, 40)
    np.testing.assert_allclose(np.asarray(d.freqresp(w)), sys(np.exp(1j * w * 1e-4)), rtol=1e-10)


def test_complex_and_bad_inputs_refused():
    fa = L.faleso_tf(papers.FALESO_K1, papers.FALESO_K2, 2 * math.pi * 50)
    with pytest.raises(ValueError, match="real coefficients only"):
        fa.to_control()
    with pytest.raises(ValueError, match="continuous-time"):
        L.TransferFunction.from_control(control.tf([1.0], [1.0, 1.0], 0.1))
    with pytest.raises(ValueError, match="SISO"):
        L.TransferFunction.from_control(control.tf([[[1.0], [1.0]]], [[[1.0, 1.0], [1.0, 2.0]]]))
    with pytest.raises(ValueError, match="convention must be"):
        L.bode(fa, [1.0], convention="rad")

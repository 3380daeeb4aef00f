"""Paper vs ours, row by row (jaxobs.reproduce.compare): every reproduced number with a paper number beside
it is within its stated tolerance or carries its explanation.  The rows of a real run are checked by
tests/test_cli.py::test_reproduce_flux_quick_json (slow); here the rule itself, on made-up rows."""

import math
import re

from jaxobs.reproduce import flux
from jaxobs.reproduce.compare import ABSOLUTE, RELATIVE, annotate
from jaxobs.reproduce.figures import FLUX_FIGURES


def _row(paper, ours, unit="rad", experiment="e", observer="o", metric="max_abs"):
    return dict(experiment=experiment, observer=observer, metric=metric, unit=unit, paper=paper, ours=ours)


def test_tolerance_within_and_explanation():
    why = {("e", "o", "max_abs"): "because"}
    rows = annotate(
        [
            _row(0.13, 0.157),  # +21 %: within 30 %
            _row(0.25, 0.158),  # -37 %: not within, explained
            _row(0.0, 0.04),  # the paper's "none": absolute 0.05 rad
            _row(0.0, 0.012, unit="Wb", metric="flux_offset"),  # not within 0.005 Wb, no explanation
            _row(None, 1.0),  # no paper number
            _row(None, True, metric="finite"),
            _row(200.0, 211.0, unit="r/min", metric="speed"),  # 5.5 %: not within 5 %, no explanation
            _row(0.3, math.nan),  # a diverged run is never within
        ],
        why,
    )
    assert [r["within"] for r in rows] == [True, False, True, False, None, None, False, False]
    assert rows[0]["tolerance"] == RELATIVE["rad"] * 0.13 and rows[0]["explanation"] is None
    assert rows[1]["explanation"] == "because"
    assert rows[2]["tolerance"] == ABSOLUTE["rad"] and rows[3]["tolerance"] == ABSOLUTE["Wb"]
    assert rows[4]["tolerance"] is None and rows[5]["explanation"] is None
    assert rows[6]["explanation"] is None  # what the test of a real run fails on


def test_flux_explanations_name_flux_rows():
    """Every explanation is keyed by an experiment the reproduction runs (its figures' keys or the steady
    and variant names), an observer of the bank or 'drive', a metric it reports; each gives a number."""
    exps = {spec[0] for spec in FLUX_FIGURES}
    observers = set(flux.OBSERVER_NAMES) | {"drive"}
    metrics = {"max_abs", "mean", "ripple", "flux_offset", "delay_samples", "min_speed", "max_speed"}
    for (exp, obs, metric), text in flux.EXPLANATIONS.items():
        assert exp in exps and obs in observers and metric in metrics, (exp, obs, metric)
        # an explanation quantifies its cause (every one gives a number) and is one line without padding
        assert re.search(r"\d", text) and text == text.strip() and "\n" not in text, text

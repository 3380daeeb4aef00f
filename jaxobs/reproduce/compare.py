"""Paper vs ours, row by row: each reproduced number beside the paper's, within a stated tolerance or with
its explanation (:func:`annotate`).

A row (``experiment, observer, metric, unit, paper, ours``) that has a paper number gets three fields:

- ``tolerance``: how far ours may be from the paper's and still match, in the row's unit: a fraction of the
  paper's number (:data:`RELATIVE`, by unit, or :data:`METRIC_RELATIVE` by metric), or, where the paper prints
  "none" (0), an absolute bound (:data:`ABSOLUTE`: what a scope trace of the paper's scale would show as
  nothing); 0 where the paper's number is a bound (a row with ``bound="upper"``: "within 2.3 deg");
- ``within``: |ours − paper| ≤ tolerance (ours ≤ paper for an upper bound; ours == paper for a yes/no row);
- ``explanation``: why not, where not within (what was measured that explains the difference; the
  reproductions' docs/papers.md sections hold the numbers).  A row outside its tolerance without an
  explanation is a defect (tests/test_papers_rows.py).

Rows without a paper number (``paper`` None: figures only, or our own diagnostics) get None in all three.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

__all__ = ["RELATIVE", "METRIC_RELATIVE", "ABSOLUTE", "annotate"]

# the fraction of the paper's number that still matches, by unit: 30 % for numbers read off scope traces
# (the threshold for "a difference to explain"), 5 % for a speed the paper's drive is set to
RELATIVE = {"rad": 0.30, "Wb": 0.30, "ωe·Ts": 0.30, "r/min": 0.05, "deg": 0.30, "%": 0.30}
# by metric, before the unit's: a speed-estimate error (r/min) is read off a scope trace, not set
METRIC_RELATIVE = {"max_speed_err": 0.30}
# where the paper prints "none" (0): the largest value a scope trace would show as nothing (000 Figs 21-22
# are drawn at about 1 rad and 0.2 Wb per division: 5 % and 2.5 % of a division; 002 prints the FA-LESO's
# mean error as "nearly 0" with its fluctuation within 2.3 deg: a mean under a quarter of that reads as 0)
ABSOLUTE = {"rad": 0.05, "Wb": 0.005, "deg": 0.5}


def annotate(rows: list[dict[str, Any]], explanations: Mapping[tuple[str, str, str], str]) -> list[dict[str, Any]]:
    """Add ``tolerance``, ``within`` and ``explanation`` to each row (module doc), in place.

    Args:
        rows: the rows {experiment, observer, metric, unit, paper, ours[, bound]}.
        explanations: (experiment, observer, metric) → why ours differs, used where a row is not within.

    Returns:
        ``rows``.
    """
    for r in rows:
        paper, ours = r["paper"], r["ours"]
        if paper is None:
            r.update(tolerance=None, within=None, explanation=None)
            continue
        unit = r["unit"]
        if isinstance(paper, bool) or isinstance(ours, bool):  # a yes/no the paper states ("cannot complete")
            tol, within = None, bool(ours == paper)
        elif r.get("bound") == "upper":
            tol, within = 0.0, bool(math.isfinite(ours) and ours <= paper)
        else:
            rel = METRIC_RELATIVE.get(r["metric"], RELATIVE[unit])
            tol = ABSOLUTE[unit] if paper == 0 else rel * abs(paper)
            within = bool(math.isfinite(ours) and abs(ours - paper) <= tol)
        why = None if within else explanations.get((r["experiment"], r["observer"], r["metric"]))
        r.update(tolerance=tol, within=within, explanation=why)
    return rows

"""Paper vs ours, row by row: each reproduced number beside the paper's, within a stated tolerance or with
its explanation (:func:`annotate`).

A row (``experiment, observer, metric, unit, paper, ours``) that has a paper number gets three fields:

- ``tolerance``: how far ours may be from the paper's and still match, in the row's unit: a fraction of the
  paper's number (:data:`RELATIVE`, by unit), or, where the paper prints "none" (0), an absolute bound
  (:data:`ABSOLUTE`: what a scope trace of the paper's scale would show as nothing);
- ``within``: |ours − paper| ≤ tolerance;
- ``explanation``: why not, where not within (what was measured that explains the difference; the
  reproductions' docs/papers.md sections hold the numbers).  A row outside its tolerance without an
  explanation is a defect (tests/test_papers_rows.py).

Rows without a paper number (``paper`` None: figures only, or our own diagnostics) get None in all three.
"""

from __future__ import annotations

import math

__all__ = ["RELATIVE", "ABSOLUTE", "annotate"]

# the fraction of the paper's number that still matches, by unit: 30 % for numbers read off scope traces
# (the threshold for "a difference to explain"), 5 % for a speed the paper's drive is set to
RELATIVE = {"rad": 0.30, "Wb": 0.30, "ωe·Ts": 0.30, "r/min": 0.05}
# where the paper prints "none" (0): the largest value a scope trace would show as nothing (000 Figs 21-22
# are drawn at about 1 rad and 0.2 Wb per division: 5 % and 2.5 % of a division)
ABSOLUTE = {"rad": 0.05, "Wb": 0.005}


def annotate(rows, explanations: dict):
    """Add ``tolerance``, ``within`` and ``explanation`` to each row (module doc), in place; returns ``rows``.
    ``explanations``: (experiment, observer, metric) → why ours differs, used where a row is not within."""
    for r in rows:
        paper, ours = r["paper"], r["ours"]
        if paper is None or isinstance(ours, bool):
            r.update(tolerance=None, within=None, explanation=None)
            continue
        unit = r["unit"]
        tol = ABSOLUTE[unit] if paper == 0 else RELATIVE[unit] * abs(paper)
        within = bool(math.isfinite(ours) and abs(ours - paper) <= tol)
        why = None if within else explanations.get((r["experiment"], r["observer"], r["metric"]))
        r.update(tolerance=tol, within=within, explanation=why)
    return rows

"""A tune job's walk through the code (benchmarks/walk.py): no module is entered from more than three places of the
flow (a module entered from a fourth does more than one job, or the flow bounces through it), and no callee calls
back up into a caller's module."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_the_default_job_enters_no_module_more_than_three_times():
    from benchmarks.walk import walk

    entries, climbs = walk(ROOT / "tuning" / "presets" / "sogi_fll.toml", steps=2, depth=3)
    per = Counter(m for m, _ in entries)
    assert len(per) >= 15  # the walk saw the job's modules (the orchestration, the objective, the writers)
    worst = per.most_common(1)[0]
    assert worst[1] <= 3, [e for e in entries if e[0] == worst[0]]
    assert not climbs, climbs

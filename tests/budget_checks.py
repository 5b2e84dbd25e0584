"""What a `--minutes` run's log shows however loaded the machine was (posenet.training.budget): the
schedule's end only comes forward, the decay's rate never rises, and the last rate is the cosine's end
to within the run's own last steps."""

from __future__ import annotations

import math


def assert_the_decay_ends_at_the_budget(
    rows: list[dict], fitted: int, schedule: int, anneal_point: float
) -> None:
    """`rows`: a budgeted run's log, one row a step (its lr and step_s); `fitted`: the total printed when
    the cosine began; `schedule`: the total saved in its checkpoint (schedule_steps)."""
    last, peak = rows[-1]["step"], max(r["lr"] for r in rows)
    assert last <= schedule <= fitted  # a slower machine brings the end forward, never back
    decay = rows[max(i for i, r in enumerate(rows) if r["lr"] == peak) + 1 :]  # after the last flat step
    assert all(b["lr"] <= a["lr"] for a, b in zip(decay, decay[1:], strict=False))  # never rises
    # TimeBudget keeps the cosine's progress at the scheduler's next step (it = step + 1) at least the
    # decay's share of its time gone. The last step's rate was set two steps before it ended, so its
    # progress lags the end by at most those two steps' time over the decay's time before the last step
    # (the deadline lies past it), plus one step of the schedule's decay, 1 / ((1 - a) last), where the
    # run ended at its total. Timed from the first decayed row, not the freeze: a shorter decay, a looser
    # bound. A decay of fewer than two steps (a machine so loaded that a step outlasts it) bounds nothing.
    if len(decay) < 2:
        return
    elapsed = sum(r["step_s"] for r in decay) - decay[-1]["step_s"]
    lag = (decay[-1]["step_s"] + decay[-2]["step_s"]) / elapsed + 1 / ((1 - anneal_point) * last)
    assert rows[-1]["lr"] <= peak * (1 + math.cos(math.pi * (1 - min(lag, 1.0)))) / 2, (lag, rows[-1])

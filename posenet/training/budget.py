"""A wall-time budget for training: the schedule's length fitted, while the run goes, to end at the budget.

`posenet train --minutes M` does not guess a step count from a separate probe (whose start-up, loader
processes and warm-up kernels make it a poor guide to the steady state). It trains: after the first
`PROBE_STEPS` steps (or a tenth of the budget, if that comes first) it times the recent steps (the
later half of those done, none of the first `SKIP_STEPS`) and fits the schedule's total so that the
steps left fill the time left; it refits after every step while the learning rate is flat, so a machine
that speeds up or slows down moves the end with it, and fixes
the total when the cosine decay begins (at anneal_point of it), so the decay is one smooth cosine that
ends at the budget. Everything from the call's start counts: set-up, loader start, checkpoints. Should
the machine slow down during the decay, the total is brought forward (never back) so that the cosine's
progress keeps up with the decay's share of its time gone: the run still stops at the budget, and its
last learning rate is within two steps' time of the cosine's end, not wherever the slower steps left it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from posenet.errors import PosenetError

SKIP_STEPS = 5  # steps not timed: the first batches wait for the loader processes and warm-up kernels
PROBE_STEPS = 15  # steps before the first fit, or fewer once PROBE_SHARE of the budget is spent
PROBE_SHARE = 0.1
UNFITTED = 2**62  # the total before the first fit: no end in sight, so the learning rate stays flat


@dataclass
class TimeBudget:
    """The schedule's total steps fitted to `seconds` of wall time from `start`."""

    seconds: float
    anneal_point: float
    total: int = UNFITTED  # the schedule's total steps (until the first fit: the lr stays flat)
    start: float = field(default_factory=time.perf_counter)
    fitted: bool = False  # the total follows the measured step time
    frozen: bool = False  # the cosine has begun: the total no longer grows
    decay_start: float = 0.0  # when the cosine began
    _times: list[float] = field(default_factory=list)  # the time each step ended, from step 1

    @property
    def deadline(self) -> float:
        return self.start + self.seconds

    def update(self, step: int, now: float) -> bool:
        """After `step` steps at time `now`: refit the total while the learning rate is flat, then during
        the decay bring it forward where the clock runs ahead of the steps. Returns True when this call
        fixed the fit (the cosine begins)."""
        self._times.append(now)
        if self.frozen:
            self._keep_up(step, now)
            return False
        probed = step >= PROBE_STEPS or now - self.start >= PROBE_SHARE * self.seconds
        if step <= SKIP_STEPS or not probed:
            return False
        since = max(SKIP_STEPS, step // 2)  # the step the timed window starts after
        step_s = (now - self._times[since - 1]) / (step - since)
        self.total = max(step + 1, step + int((self.deadline - now) / step_s))
        self.fitted = True
        if step >= self.anneal_point * self.total:
            self.frozen, self.decay_start = True, now
        return self.frozen

    def _keep_up(self, step: int, now: float) -> None:
        """During the decay: the cosine's progress at the next step, (it / total - a) / (1 - a) for
        it = step + 1 and a = anneal_point, at least the decay's share of its time gone, by bringing the
        total forward where the steps have fallen behind the clock. It never grows: the rate never rises."""
        gone = min((now - self.decay_start) / max(self.deadline - self.decay_start, 1e-9), 1.0)
        share = self.anneal_point + (1 - self.anneal_point) * gone  # of the total, `step + 1` must reach
        if share > 0:
            self.total = min(self.total, max(step + 1, int((step + 1) / share)))

    def expired(self, now: float) -> bool:
        return now >= self.deadline


def run_budget(
    minutes: float | None, anneal_point: float, resume: bool, max_steps: int | None
) -> TimeBudget | None:
    """The time budget of a new run given `--minutes` (None without one), started now; a budget fits a
    whole schedule, so it refuses a resumed run and a step cap."""
    if minutes is None:
        return None
    if resume or max_steps is not None:
        raise PosenetError("--minutes fits a new run's whole schedule: it takes no --resume or --max-steps")
    return TimeBudget(60 * minutes, anneal_point)

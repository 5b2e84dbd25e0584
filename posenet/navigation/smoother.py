"""The Rauch-Tung-Striebel fixed-interval smoother over a filter's steps: the best trajectory of a
recorded sequence, each frame's estimate from every measurement before and after it.

On the error state of the MEKF (posenet.navigation.filter), from the last step back:

    C_k = P_k|k Phi_k+1^T P_k+1|k^-1,    d = x_k+1|N [-] x_k+1|k,
    x_k|N = x_k|k [+] C_k d,             P_k|N = P_k|k + C_k (P_k+1|N - P_k+1|k) C_k^T

with [+] and [-] the state's own (the attitude by exp and log on the right). The two covariances of the
difference refer to slightly different attitudes; that is ignored to first order, as is usual. A restart
(a part taken afresh from a measurement) cuts the chain: each run between restarts is smoothed alone.
Frames before the start have no estimate. Pure numpy.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from posenet.navigation.filter import NavState, Step, one_blas_thread


def smooth(history: list[Step]) -> list[NavState | None]:
    """The smoothed state of each step of `history` (a PoseFilter's), None where the filter had none."""
    with one_blas_thread():  # small matrices: posenet.navigation.filter
        return _smooth(history)


def _smooth(history: list[Step]) -> list[NavState | None]:
    out: list[NavState | None] = [s.posterior for s in history]
    later: NavState | None = None  # the smoothed state of the step after k
    for k in range(len(history) - 1, -1, -1):
        step = history[k]
        if step.posterior is None:
            later = None
            continue
        nxt = history[k + 1] if k + 1 < len(history) else None
        if later is None or nxt is None or nxt.restarted or nxt.prior is None or nxt.phi is None:
            later = step.posterior  # the chain's last step: its filtered state is its smoothed one
            out[k] = later
            continue
        # P_k|k Phi^T P_k+1|k^+ (the pseudo-inverse: a state of zero variance, the bias of a part with
        # nothing persistent, takes no gain)
        C = step.posterior.P @ nxt.phi.T @ np.linalg.pinv(nxt.prior.P, hermitian=True)
        d = later.minus(nxt.prior)
        P = step.posterior.P + C @ (later.P - nxt.prior.P) @ C.T
        smoothed = step.posterior.plus(C @ d)
        later = replace(smoothed, P=0.5 * (P + P.T))
        out[k] = later
    return out

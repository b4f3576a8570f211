"""The metrics of a tendon set, the same for every extractor
(``docs/method.md``, extraction)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .protocol import IdealizedState, Tendon


@dataclass
class MetricSettings:
    """``kink_angle`` (degrees) above which a turn is a kink; ``mu`` the friction
    coefficient of the capstan factor exp(-mu Theta)."""

    kink_angle: float = 30.0
    mu: float = 0.1


def tendon_metrics(problem, state: IdealizedState, tendons: list[Tendon],
                   settings: MetricSettings | None = None) -> dict:
    """The metrics of ``docs/method.md`` (extraction), the same for every extractor (SI units,
    angles in radians): ``count``, ``total_length``, ``lengths``, ``total_turning``
    (sum of |turn angles| over all tendons), ``max_turn``, ``kinks``, ``capstan``
    (exp(-mu Theta) per tendon) and ``capstan_worst``, ``tension_cv`` (the largest
    coefficient of variation of the tension along a source strand, over the
    tendons; ``tension_cvs`` per tendon) and ``coverage`` (the share of the
    idealized active tension-length sum tau_i a0_i that the tendons' fibers carry)."""
    s = settings or MetricSettings()
    a0 = problem.fibers.a0
    turns = [t.turn_angles() for t in tendons]
    theta = np.array([tt.sum() for tt in turns]) if tendons else np.zeros(0)
    all_turns = np.concatenate(turns) if turns else np.zeros(0)
    capstan = np.exp(-s.mu * theta)
    cvs = np.array([t.tension_std / t.tension if t.tension > 0 else 0.0 for t in tendons])
    active = state.active
    total = float((state.tau[active] * a0[active]).sum())
    used = np.zeros(len(a0), dtype=bool)
    for t in tendons:
        used[t.fibers] = True
    covered = float((state.tau[active & used] * a0[active & used]).sum())
    return {
        "count": len(tendons),
        "total_length": float(sum(t.length for t in tendons)),
        "lengths": [t.length for t in tendons],
        "total_turning": float(theta.sum()),
        "max_turn": float(all_turns.max()) if len(all_turns) else 0.0,
        "kinks": int((all_turns > math.radians(s.kink_angle)).sum()),
        "capstan": capstan.tolist(),
        "capstan_worst": float(capstan.min()) if len(capstan) else 1.0,
        "tension_cv": float(cvs.max()) if len(cvs) else 0.0,
        "tension_cvs": cvs.tolist(),
        "coverage": covered / total if total > 0 else 0.0,
    }

"""The objective: the sum of its terms over the poses' equilibria."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .term import State, Term


def union_tension(taus: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The union tension ``tau_u = sqrt(sum_p tau_p^2)`` (C,) of per-pose tensions
    ``taus`` (P, C), N, and its derivative d tau_u / d tau_p (P, C) (0 where all
    are slack). One pose: ``tau_u = tau`` and derivative 1, exactly."""
    taus = np.asarray(taus, dtype=float)
    if len(taus) == 1:
        return taus[0], np.ones_like(taus)
    tu = np.sqrt((taus * taus).sum(axis=0))
    return tu, np.divide(taus, tu, out=np.zeros_like(taus), where=tu > 0)


@dataclass
class Evaluation:
    """The summed objective at the poses' states: ``total``, ``terms`` (value per
    name), and the summed partials per pose ``dx`` (P, n, 2), ``dtau`` (P, C) and
    ``dac`` (P, C)."""

    total: float
    terms: dict[str, float]
    dx: np.ndarray
    dtau: np.ndarray
    dac: np.ndarray


class Objective:
    """The sum of its terms; only the terms named in ``active`` count in this stage
    (the others report 0: stage 0 is plain soft IK)."""

    def __init__(self, terms: list[Term]):
        self.terms = list(terms)
        self.active = {t.name for t in self.terms}

    def term(self, name: str) -> Term:
        return next(t for t in self.terms if t.name == name)

    def evaluate(self, states: list[State]) -> Evaluation:
        """At one state per pose: the union terms see the union tension (chained back
        to each pose's tensions), the others are summed over the poses."""
        P, n, C = len(states), states[0].x.shape[0], states[0].tau.shape[0]
        dx, dtau, dac = np.zeros((P, n, 2)), np.zeros((P, C)), np.zeros((P, C))
        tu, dtu = union_tension([s.tau for s in states])
        values, total = {}, 0.0
        for t in self.terms:
            if t.name not in self.active:
                values[t.name] = 0.0
                continue
            if t.union:
                tv = t.evaluate(State(states[0].x, states[0].ac, tu))
                values[t.name] = tv.value
                if tv.dtau is not None:
                    dtau += tv.dtau * dtu
            else:
                values[t.name] = 0.0
                for p, s in enumerate(states):
                    tv = t.evaluate(s)
                    values[t.name] += tv.value
                    for acc, part in ((dx, tv.dx), (dtau, tv.dtau), (dac, tv.dac)):
                        if part is not None:
                            acc[p] += part
            total += values[t.name]
        return Evaluation(total, values, dx, dtau, dac)

"""Objective terms over the fiber contractions (DESIGN.md section 3).

Each term is evaluated at an equilibrium ``x*(ac)`` and returns its value and
its partial derivatives with respect to the node positions ``x`` (directly),
the tensions ``tau`` and the contractions ``ac`` (explicitly). The optimizer
chains them: tensions depend on both ``x`` and ``ac``
(``dtau/dx = kc dL/dx``, ``dtau/dac = tau_ac``), and the ``x`` part goes
through one adjoint solve.

* ``pose``: ``O_pos = sum_p |x_p - x'_p|^2 / L^2`` (targets are embedded material points);
* ``sparsity``: ``O_sp = w_sp sum_i m_i s_k(tau_i)`` with the smoothstep
  ``s_k(t) = 3u^2 - 2u^3``, ``u = t/k`` on ``0 < t < k`` (0 below, 1 above);
  ``m_i = a0_i / L`` ("length") or 1 ("count");
* ``continuity``: ``O_ct = w_ct sum_(a,b) m_ab cos^2(theta_ab) ((tau_a - tau_b)/tau_ref)^2``
  over fiber pairs sharing a node, ``m_ab = (a0_a + a0_b) / (2L)`` or 1;
* ``contraction``: ``O_reg = w_ac sum_i (ac_i / a0_i)^2``;
* ``strand_end``: ``O_end = w_end sum_v ((T1 - T2)^2 + (T3 + T4 + ...)^2) / tau_ref^2``
  over the fiber nodes ``v`` outside the clamped band, ``T1 >= T2 >= ...`` the
  tensions of the fibers meeting at ``v``: zero inside a clean strand (two equal
  tensions), positive at a strand's end, a star or a tension jump - so each
  extra tendon costs, and hinges of short fibers become expensive. With the
  ``"count"`` measure it is a smooth L0 of the same imbalance,
  ``O_end = w_end sum_v s_(k^2)(E_v)``, ``E_v = (T1 - T2)^2 + (T3 + T4 + ...)^2``:
  every end at least ``k`` (the sparsity's homotopy parameter) out of balance
  costs ``w_end`` whatever its tension - a count of strand ends. With the
  ``"linear"`` measure it is the imbalance's magnitude,
  ``O_end = w_end sum_v (sqrt(E_v + eps^2) - eps) / tau_ref``, ``eps = END_EPS tau_ref``
  (smooth where a strand is balanced): an end costs in proportion to its tension,
  so splitting a strand into two parallel ones at half the tension saves nothing
  on its ends (with the squared imbalance it halves their cost);
* ``effort``: ``O_eff = w_eff sum_i (a0_i / L) tau_i / tau_ref``, the actuation
  effort (tension times length): antagonist fibers pulling against each other
  (co-contraction) cost, so fibers that need not pull are paid out.

Several poses (a scene's ``[[poses]]``): each pose ``p`` has its own
contractions and equilibrium; ``pose``, ``contraction`` and ``effort`` are
summed over the poses, while the layout terms (``sparsity``, ``continuity``, ``strand_end``)
act on the union tension ``tau_u = sqrt(sum_p tau_p^2)`` - a fiber is active if
it is active in any pose, and a strand keeps one tension in each pose. With
one pose ``tau_u = tau``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from .problem import Problem


@dataclass
class TermValue:
    """A term's value and partial derivatives (None where it does not depend):
    ``dx`` (n, 2) w.r.t. node positions, ``dtau`` (C,), ``dac`` (C,) explicit."""

    value: float
    dx: np.ndarray | None = None
    dtau: np.ndarray | None = None
    dac: np.ndarray | None = None


#: the terms that act on the union of the poses (the layout) rather than on each pose
UNION_TERMS = ("sparsity", "continuity", "strand_end")


@dataclass
class State:
    """An equilibrium to evaluate terms at: positions ``x`` (n, 2), contractions
    ``ac`` (C,) m, tensions ``tau`` (C,) N, of pose number ``pose``."""

    x: np.ndarray
    ac: np.ndarray
    tau: np.ndarray
    pose: int = 0


def union_tension(taus: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The union tension ``tau_u = sqrt(sum_p tau_p^2)`` (C,) of per-pose tensions
    ``taus`` (P, C), N, and its derivative d tau_u / d tau_p (P, C) (0 where all
    are slack). One pose: ``tau_u = tau`` and derivative 1, exactly."""
    taus = np.asarray(taus, dtype=float)
    if len(taus) == 1:
        return taus[0], np.ones_like(taus)
    tu = np.sqrt((taus * taus).sum(axis=0))
    return tu, np.divide(taus, tu, out=np.zeros_like(taus), where=tu > 0)


class Term(Protocol):
    """An objective term: a ``name`` and ``evaluate(state) -> TermValue``."""

    name: str

    def evaluate(self, state: State) -> TermValue: ...


def smoothstep(t: np.ndarray, k: float) -> tuple[np.ndarray, np.ndarray]:
    """s_k(t) and s_k'(t): 0 for t <= 0, 3u^2 - 2u^3 (u = t/k) on (0, k), 1 for t >= k."""
    u = np.clip(np.asarray(t, dtype=float) / k, 0.0, 1.0)
    s = u * u * (3.0 - 2.0 * u)
    ds = np.where((u > 0.0) & (u < 1.0), 6.0 * u * (1.0 - u) / k, 0.0)
    return s, ds


class PoseTerm:
    """O_pos = sum_p |x_p - goal_p|^2 / L^2 over the targets of the state's pose."""

    name = "pose"

    def __init__(self, problem: Problem):
        self.poses = [problem.pose(i) for i in range(problem.n_poses)]
        self.L2 = problem.size ** 2

    def evaluate(self, state: State) -> TermValue:
        p = self.poses[state.pose]
        diff = p.target_positions(state.x) - p.target_goal  # (t, 2)
        dx = np.zeros_like(state.x)
        corners = p.mesh.triangles[p.target.tri]  # (t, 3)
        for j in range(3):
            np.add.at(dx, corners[:, j], (2.0 / self.L2) * p.target.bary[:, j:j + 1] * diff)
        return TermValue(float((diff * diff).sum() / self.L2), dx=dx)


class SparsityTerm:
    """O_sp = weight sum_i m_i s_k(tau_i); ``k`` (N) is set per homotopy stage."""

    name = "sparsity"

    def __init__(self, problem: Problem, weight: float, measure: str = "length", k: float = 1.0):
        self.weight, self.k = weight, k
        self.m = problem.fibers.a0 / problem.size if measure == "length" else np.ones(problem.fibers.n_fibers)

    def evaluate(self, state: State) -> TermValue:
        s, ds = smoothstep(state.tau, self.k)
        return TermValue(float(self.weight * np.dot(self.m, s)), dtau=self.weight * self.m * ds)


class ContinuityTerm:
    """O_ct = weight sum_(a,b) m_ab cos^2_ab ((tau_a - tau_b)/tau_ref)^2."""

    name = "continuity"

    def __init__(self, problem: Problem, weight: float, tension_scale: float, measure: str = "length"):
        pairs = problem.fibers.pairs
        self.a, self.b = pairs.fibers[:, 0], pairs.fibers[:, 1]
        a0 = problem.fibers.a0
        m = (a0[self.a] + a0[self.b]) / (2.0 * problem.size) if measure == "length" else 1.0
        self.c = weight * m * pairs.cos2 / tension_scale ** 2
        self.n_fibers = problem.fibers.n_fibers

    def evaluate(self, state: State) -> TermValue:
        d = state.tau[self.a] - state.tau[self.b]
        g = 2.0 * self.c * d
        dtau = np.bincount(self.a, g, self.n_fibers) - np.bincount(self.b, g, self.n_fibers)
        return TermValue(float(np.dot(self.c, d * d)), dtau=dtau)


class ContractionTerm:
    """O_reg = weight sum_i (ac_i / a0_i)^2 over cables of rest lengths ``a0`` (m)."""

    name = "contraction"

    def __init__(self, a0: np.ndarray, weight: float):
        self.weight, self.a0 = weight, np.asarray(a0, dtype=float)

    def evaluate(self, state: State) -> TermValue:
        r = state.ac / self.a0
        return TermValue(float(self.weight * np.dot(r, r)), dac=2.0 * self.weight * r / self.a0)


class EffortTerm:
    """O_eff = weight sum_i (a0_i / L) tau_i / tau_ref (per pose)."""

    name = "effort"

    def __init__(self, problem: Problem, weight: float, tension_scale: float):
        self.c = weight * problem.fibers.a0 / (problem.size * tension_scale)

    def evaluate(self, state: State) -> TermValue:
        return TermValue(float(np.dot(self.c, state.tau)), dtau=self.c.copy())


#: the "linear" strand-end measure's smoothing, x tau_ref
END_EPS = 0.01


class StrandEndTerm:
    """O_end = weight sum_v E_v / tau_ref^2 (``measure`` "tension"), weight sum_v
    s_(k^2)(E_v) (``measure`` "count"; ``k`` in N, set per homotopy stage) or
    weight sum_v (sqrt(E_v + eps^2) - eps) / tau_ref (``measure`` "linear",
    ``eps = END_EPS tau_ref``) with
    ``E_v = (T1 - T2)^2 + (T3 + ...)^2`` (N^2) over the fiber nodes away from the
    clamped band (a node whose triangle has a clamped corner does not count:
    tendons may end at the base, where motors sit)."""

    name = "strand_end"

    def __init__(self, problem: Problem, weight: float, tension_scale: float, measure: str = "tension",
                 k: float = 1.0):
        fib = problem.fibers
        self.measure, self.k = measure, k
        self.weight = weight / tension_scale ** {"tension": 2, "linear": 1, "count": 0}[measure]  # O_end's units
        self.eps = END_EPS * tension_scale
        self.n_fibers = fib.n_fibers
        free = ~problem.fixed[problem.mesh.triangles[fib.embedding.tri]].any(axis=1)  # (k,)
        start, ids = fib.incidence
        count = np.diff(start)
        nodes = np.flatnonzero(free & (count > 0))
        c = count[nodes]
        # (V, D) incident fiber ids per counted node, padded with n_fibers (tension 0)
        self.incident = np.full((len(nodes), max(int(c.max()) if len(c) else 2, 2)), fib.n_fibers,
                                dtype=np.int64)
        rows = np.repeat(np.arange(len(nodes)), c)
        cols = np.arange(len(rows)) - np.repeat(np.cumsum(c) - c, c)
        self.incident[rows, cols] = ids[np.repeat(free & (count > 0), count)]

    def evaluate(self, state: State) -> TermValue:
        T = np.append(state.tau, 0.0)[self.incident]  # (V, D)
        order = np.argsort(-T, axis=1, kind="stable")
        Ts = np.take_along_axis(T, order, axis=1)
        jump = Ts[:, 0] - Ts[:, 1]
        rest = Ts[:, 2:].sum(axis=1)
        E = jump * jump + rest * rest  # (V,)
        g = np.empty_like(Ts)  # dE/dTs
        g[:, 0], g[:, 1] = 2.0 * jump, -2.0 * jump
        g[:, 2:] = 2.0 * rest[:, None]
        if self.measure == "count":
            s, ds = smoothstep(E, self.k * self.k)
            value, g = float(s.sum()), g * ds[:, None]
        elif self.measure == "linear":
            r = np.sqrt(E + self.eps * self.eps)
            value, g = float((r - self.eps).sum()), g * (0.5 / r)[:, None]
        else:
            value = float(E.sum())
        fib_sorted = np.take_along_axis(self.incident, order, axis=1)
        dtau = np.bincount(fib_sorted.ravel(), self.weight * g.ravel(), self.n_fibers + 1)[:-1]
        return TermValue(self.weight * value, dtau=dtau)


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

    def term(self, name: str):
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
            if t.name in UNION_TERMS:
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

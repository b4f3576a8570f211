"""The built-in terms of the objective over the fiber contractions, in the
order the objective sums them (see ``docs/method.md``).

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
* ``contraction``: ``O_reg = w_ac sum_i (ac_i / a0_i)^2``;
* ``effort``: ``O_eff = w_eff sum_i (a0_i / L) tau_i / tau_ref``, the actuation
  effort (tension times length): antagonist fibers pulling against each other
  (co-contraction) cost, so fibers that need not pull are paid out.

Several poses (a scene's ``[[poses]]``): each pose ``p`` has its own
contractions and equilibrium; ``pose``, ``contraction`` and ``effort`` are
summed over the poses, while the layout terms (``sparsity``, ``continuity``,
``strand_end``) act on the union tension ``tau_u = sqrt(sum_p tau_p^2)`` - a
fiber is active if it is active in any pose, and a strand keeps one tension in
each pose. With one pose ``tau_u = tau``.

Adding a term is one new subclass of :class:`~tendon_taichi.objective.term.Term`
in this module (it joins the objective, the scene format, the command line and
the documentation's table).
"""

from __future__ import annotations

import numpy as np

from .setting import Setting
from .term import State, Term, TermValue

MEASURES = ("length", "count")
#: the "linear" strand-end measure's smoothing, x tau_ref
END_EPS = 0.01


def registered() -> list[type[Term]]:
    """Every term, in the objective's order: the built-in ones of this module, then
    any defined elsewhere."""
    return list(Term.registry.values())


def smoothstep(t: np.ndarray, k: float) -> tuple[np.ndarray, np.ndarray]:
    """s_k(t) and s_k'(t): 0 for t <= 0, 3u^2 - 2u^3 (u = t/k) on (0, k), 1 for t >= k."""
    u = np.clip(np.asarray(t, dtype=float) / k, 0.0, 1.0)
    s = u * u * (3.0 - 2.0 * u)
    ds = np.where((u > 0.0) & (u < 1.0), 6.0 * u * (1.0 - u) / k, 0.0)
    return s, ds


class PoseTerm(Term):
    """O_pos = sum_p |x_p - goal_p|^2 / L^2 over the targets of the state's pose."""

    name = "pose"
    lattice = False

    def __init__(self, problem):
        self.poses = [problem.pose(i) for i in range(problem.n_poses)]
        self.L2 = problem.size ** 2

    @classmethod
    def from_settings(cls, problem, settings, a0):
        return cls(problem)

    def evaluate(self, state: State) -> TermValue:
        p = self.poses[state.pose]
        diff = p.target_positions(state.x) - p.target_goal  # (t, dim)
        dx = np.zeros_like(state.x)
        corners = p.mesh.triangles[p.target.tri]  # (t, 3)
        for j in range(3):
            np.add.at(dx, corners[:, j], (2.0 / self.L2) * p.target.bary[:, j:j + 1] * diff)
        return TermValue(float((diff * diff).sum() / self.L2), dx=dx)


class SparsityTerm(Term):
    """O_sp = weight sum_i m_i s_k(tau_i); ``k`` (N) is set per homotopy stage."""

    name = "sparsity"
    settings = (Setting("sparsity", 1.0e-4, "L0 sparsity weight w_sp", ge=0.0),
                Setting("sparsity_measure", "length", "what one active fiber costs: its length "
                        "(resolution independent) or 1 (the paper's literal count)", kind=str, choices=MEASURES))
    union = homotopy = uses_k = True

    def __init__(self, problem, weight: float, measure: str = "length", k: float = 1.0):
        self.weight, self.k = weight, k
        self.m = problem.fibers.a0 / problem.size if measure == "length" else np.ones(problem.fibers.n_fibers)

    @classmethod
    def from_settings(cls, problem, s, a0):
        return cls(problem, s.sparsity, s.sparsity_measure, s.homotopy.k0)

    def evaluate(self, state: State) -> TermValue:
        s, ds = smoothstep(state.tau, self.k)
        return TermValue(float(self.weight * np.dot(self.m, s)), dtau=self.weight * self.m * ds)


class ContinuityTerm(Term):
    """O_ct = weight sum_(a,b) m_ab cos^2_ab ((tau_a - tau_b)/tau_ref)^2."""

    name = "continuity"
    settings = (Setting("continuity", 2.5e-5, "directional continuity weight w_ct", ge=0.0),
                Setting("continuity_measure", "length", "what one fiber pair weighs: its length or 1",
                        kind=str, choices=MEASURES))
    union = homotopy = True

    def __init__(self, problem, weight: float, tension_scale: float, measure: str = "length"):
        pairs = problem.fibers.pairs
        self.a, self.b = pairs.fibers[:, 0], pairs.fibers[:, 1]
        a0 = problem.fibers.a0
        m = (a0[self.a] + a0[self.b]) / (2.0 * problem.size) if measure == "length" else 1.0
        self.c = weight * m * pairs.cos2 / tension_scale ** 2
        self.n_fibers = problem.fibers.n_fibers

    @classmethod
    def from_settings(cls, problem, s, a0):
        return cls(problem, s.continuity, s.tension_scale, s.continuity_measure)

    def evaluate(self, state: State) -> TermValue:
        d = state.tau[self.a] - state.tau[self.b]
        g = 2.0 * self.c * d
        dtau = np.bincount(self.a, g, self.n_fibers) - np.bincount(self.b, g, self.n_fibers)
        return TermValue(float(np.dot(self.c, d * d)), dtau=dtau)


class StrandEndTerm(Term):
    """O_end = weight sum_v E_v / tau_ref^2 (``measure`` "tension"), weight sum_v
    s_(k^2)(E_v) (``measure`` "count"; ``k`` in N, set per homotopy stage) or
    weight sum_v (sqrt(E_v + eps^2) - eps) / tau_ref (``measure`` "linear",
    ``eps = END_EPS tau_ref``) with
    ``E_v = (T1 - T2)^2 + (T3 + ...)^2`` (N^2) over the fiber nodes away from the
    clamped band (a node whose triangle has a clamped corner does not count:
    tendons may end at the base, where motors sit)."""

    name = "strand_end"
    #: the power of tau_ref that makes each measure's value dimensionless
    POWERS = {"tension": 2, "linear": 1, "count": 0}
    settings = (Setting("strand_end", 1.0e-4, "strand-end weight w_end (tension imbalance at fiber nodes)", ge=0.0),
                Setting("strand_end_measure", "tension", "the imbalance's cost: squared (tension), a smooth L0 "
                        "count of ends (count) or its magnitude (linear)", kind=str, choices=tuple(POWERS)))
    union = homotopy = uses_k = True

    def __init__(self, problem, weight: float, tension_scale: float, measure: str = "tension",
                 k: float = 1.0):
        fib = problem.fibers
        self.measure, self.k = measure, k
        self.weight = weight / tension_scale ** self.POWERS[measure]  # O_end's units
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

    @classmethod
    def from_settings(cls, problem, s, a0):
        return cls(problem, s.strand_end, s.tension_scale, s.strand_end_measure, s.homotopy.k0)

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


class ContractionTerm(Term):
    """O_reg = weight sum_i (ac_i / a0_i)^2 over cables of rest lengths ``a0`` (m)."""

    name = "contraction"
    settings = (Setting("contraction_reg", 1.0e-6, "contraction regularizer weight w_ac", ge=0.0),)
    lattice = False

    def __init__(self, a0: np.ndarray, weight: float):
        self.weight, self.a0 = weight, np.asarray(a0, dtype=float)

    @classmethod
    def from_settings(cls, problem, s, a0):
        return cls(a0, s.contraction_reg)

    def evaluate(self, state: State) -> TermValue:
        r = state.ac / self.a0
        return TermValue(float(self.weight * np.dot(r, r)), dac=2.0 * self.weight * r / self.a0)


class EffortTerm(Term):
    """O_eff = weight sum_i (a0_i / L) tau_i / tau_ref (per pose)."""

    name = "effort"
    settings = (Setting("effort", 0.0, "actuation-effort weight w_eff (tension x length, in every pose; "
                        "against co-contraction)", ge=0.0),)
    homotopy = True

    def __init__(self, problem, weight: float, tension_scale: float):
        self.c = weight * problem.fibers.a0 / (problem.size * tension_scale)

    @classmethod
    def from_settings(cls, problem, s, a0):
        return cls(problem, s.effort, s.tension_scale)

    def evaluate(self, state: State) -> TermValue:
        return TermValue(float(np.dot(self.c, state.tau)), dtau=self.c.copy())

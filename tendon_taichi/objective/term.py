"""The term protocol and its registry.

A term of the objective is one subclass of :class:`Term`. Defining the class
registers it; the class declares everything the rest of the program derives
from it: its ``name`` (the key of its value in every summary and recording),
its :class:`~tendon_taichi.objective.setting.Setting` s (the scene's
``[optimize]`` keys and the command-line flags), whether it acts on the union
of the poses' tensions (``union``), whether it is on only in the homotopy
stages (``homotopy``: off in stage 0, the plain soft IK), whether it needs the
fiber lattice (``lattice``: off on a realizable robot, whose cables are a few
tendons) and whether it reads the homotopy's ``k`` (``uses_k``). The objective
sums the registered terms in the order they were defined.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from .setting import Setting


@dataclass
class TermValue:
    """A term's value and partial derivatives (None where it does not depend):
    ``dx`` (n, dim) w.r.t. node positions, ``dtau`` (C,), ``dac`` (C,) explicit."""

    value: float
    dx: np.ndarray | None = None
    dtau: np.ndarray | None = None
    dac: np.ndarray | None = None


@dataclass
class State:
    """An equilibrium to evaluate terms at: positions ``x`` (n, dim), contractions
    ``ac`` (C,) m, tensions ``tau`` (C,) N, of pose number ``pose``."""

    x: np.ndarray
    ac: np.ndarray
    tau: np.ndarray
    pose: int = 0


class Term:
    """Base class of the objective's terms (see the module docstring).

    A subclass sets the class attributes below and implements
    :meth:`from_settings` (build the term for a problem from the optimize
    settings) and :meth:`evaluate`."""

    name: ClassVar[str] = ""
    settings: ClassVar[tuple[Setting, ...]] = ()
    union: ClassVar[bool] = False
    homotopy: ClassVar[bool] = False
    lattice: ClassVar[bool] = True
    uses_k: ClassVar[bool] = False
    #: every defined term by name, in the order of definition (the objective's order)
    registry: ClassVar[dict[str, type["Term"]]] = {}

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if not cls.name:
            raise TypeError(f"objective term {cls.__qualname__} has no name")
        if cls.name in Term.registry:
            raise TypeError(f"two objective terms are named '{cls.name}'")
        Term.registry[cls.name] = cls

    @classmethod
    def from_settings(cls, problem, settings, a0: np.ndarray) -> "Term":
        """The term for ``problem`` and its optimize ``settings``; ``a0`` (C,) m are
        the rest lengths of the cables it acts on (fibers or tendons)."""
        raise NotImplementedError

    def evaluate(self, state: State) -> TermValue:
        """The term's value and partial derivatives at ``state``."""
        raise NotImplementedError

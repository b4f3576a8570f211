"""The Newton kernels (private to this layer): the right-hand side, the Newton
direction that the backends set, and the trial point of the line search, on a
model's buffers."""

import numpy as np

from ..physics.buffers import F64, I32, NDARRAY, dot_nodes, get_sc, get_v, k_copy_nodes, set_v, vec2
from ..physics.forces import energy
from ..physics.launch import kernel
from ..physics.layout import Scalar, Slot
from ..physics.runtime import ti


@kernel
def k_newton_rhs(fb: F64, ib: I32, serial: ti.template()):
    """CB = -G on the free DOFs."""
    ti.loop_config(serialize=serial)
    for i in range(ib[Slot.N]):
        set_v(fb, ib, Slot.CB, i, -get_v(fb, ib, Slot.G, i) * get_v(fb, ib, Slot.MASK, i))


@kernel
def k_take_direction(fb: F64, ib: I32, from_cg: ti.i32, serial: ti.template()) -> ti.f64:
    """DX = CX (or CB) on the free DOFs; return G . DX."""
    ti.loop_config(serialize=serial)
    for i in range(ib[Slot.N]):
        v = get_v(fb, ib, Slot.CB, i)
        if from_cg != 0:
            v = get_v(fb, ib, Slot.CX, i)
        set_v(fb, ib, Slot.DX, i, v * get_v(fb, ib, Slot.MASK, i))
    dot_nodes(fb, ib, Slot.G, Slot.DX, Scalar.S0, serial=serial)
    return get_sc(fb, ib, Scalar.S0)


@kernel
def k_direction_from(fb: F64, ib: I32, d_in: NDARRAY, serial: ti.template()) -> ti.f64:
    """DX = d (2n values from the host) on the free DOFs; return G . DX."""
    ti.loop_config(serialize=serial)
    for i in range(ib[Slot.N]):
        set_v(fb, ib, Slot.DX, i, vec2(d_in[2 * i], d_in[2 * i + 1]) * get_v(fb, ib, Slot.MASK, i))
    dot_nodes(fb, ib, Slot.G, Slot.DX, Scalar.S0, serial=serial)
    return get_sc(fb, ib, Scalar.S0)


@kernel
def k_trial(fb: F64, ib: I32, alpha: ti.f64, serial: ti.template()) -> vec2:
    """XT = X + alpha DX; returns (E_tot, min det fb) at XT."""
    ti.loop_config(serialize=serial)
    for i in range(ib[Slot.N]):
        set_v(fb, ib, Slot.XT, i, get_v(fb, ib, Slot.X, i) + alpha * get_v(fb, ib, Slot.DX, i))
    energy(fb, ib, Slot.XT, serial)
    return vec2(get_sc(fb, ib, Scalar.S0), get_sc(fb, ib, Scalar.JMIN))




# ---------------------------------------------------------------- host side
def newton_rhs(model) -> None:
    """CB = -G on the free DOFs (G: the model's last gradient)."""
    k_newton_rhs(model.fb, model.ib, model.serial)


def take_direction(model, from_cg: bool = True) -> float:
    """The Newton direction DX = the CG solution CX (or CB: steepest descent) on the
    free DOFs; returns G . DX."""
    return float(k_take_direction(model.fb, model.ib, 1 if from_cg else 0, model.serial))


def direction_from(model, d: np.ndarray) -> float:
    """The Newton direction from the host, d (2n,); returns G . d on the free DOFs."""
    return float(k_direction_from(model.fb, model.ib, np.ascontiguousarray(d, dtype=np.float64), model.serial))


def trial(model, alpha: float) -> tuple[float, float]:
    """XT = X + alpha DX; returns (E_tot, min det F) there."""
    E, jmin = k_trial(model.fb, model.ib, float(alpha), model.serial)
    return float(E), float(jmin)


def accept(model) -> None:
    """X = XT: the line search's trial point becomes the positions."""
    k_copy_nodes(model.fb, model.ib, Slot.XT, Slot.X, model.serial)

"""The CG kernels (private to :mod:`.cg`): preconditioned conjugate gradients on
the free DOFs with the Hessian as last prepared (:func:`~tendon_taichi.physics.forces.hessian`),
on a model's buffers. Block-Jacobi PCG runs wholly in Taichi (a whole solve in
one launch for serialized models, one launch per iteration otherwise); PCG with
a preconditioner applied on the host takes three launches per iteration."""

from ..physics.buffers import (F64, I32, NDARRAY, dot_nodes, get_cg, get_m2, get_sc, get_v, set_cg, set_sc,
                               set_v, vec2)
from ..physics.forces import apply_hessian
from ..physics.launch import kernel
from ..physics.layout import CGState, Scalar, Slot
from ..physics.runtime import ti


@ti.func
def cg_residual(fb: ti.template(), ib: ti.template(), warm: ti.i32, serial: ti.template()):
    """Mask the right-hand side CB, start CX at 0 (or the last solution, ``warm``)
    and set CR = CB - H CX; scalars BB = |CB|^2 and RR = |CR|^2."""
    ti.loop_config(serialize=serial)
    for i in range(ib[Slot.N]):
        m = get_v(fb, ib, Slot.MASK, i)
        set_v(fb, ib, Slot.CB, i, get_v(fb, ib, Slot.CB, i) * m)
        x0 = vec2(0.0, 0.0)
        if warm != 0:
            x0 = get_v(fb, ib, Slot.CX, i) * m
        set_v(fb, ib, Slot.CX, i, x0)
    apply_hessian(fb, ib, Slot.CX, Slot.CQ, True, serial=serial)
    ti.loop_config(serialize=serial)
    for i in range(ib[Slot.N]):
        set_v(fb, ib, Slot.CR, i, get_v(fb, ib, Slot.CB, i) - get_v(fb, ib, Slot.CQ, i))
    dot_nodes(fb, ib, Slot.CR, Slot.CR, Scalar.RR, serial=serial)
    dot_nodes(fb, ib, Slot.CB, Slot.CB, Scalar.BB, serial=serial)


@ti.func
def cg_begin(fb: ti.template(), ib: ti.template(), warm: ti.i32, tol: ti.f64, serial: ti.template()):
    cg_residual(fb, ib, warm, serial)
    ti.loop_config(serialize=serial)
    for i in range(ib[Slot.N]):
        z = get_m2(fb, ib, Slot.MINV, i) @ get_v(fb, ib, Slot.CR, i)
        set_v(fb, ib, Slot.CZ, i, z)
        set_v(fb, ib, Slot.CP, i, z)
    dot_nodes(fb, ib, Slot.CR, Slot.CZ, Scalar.RZ, serial=serial)
    set_sc(fb, ib, Scalar.TOL2, tol * tol * get_sc(fb, ib, Scalar.BB))
    set_cg(ib, CGState.ITERS, 0)
    set_cg(ib, CGState.NEGCURV, 0)
    set_cg(ib, CGState.DONE, 0)
    if get_sc(fb, ib, Scalar.RR) <= get_sc(fb, ib, Scalar.TOL2):
        set_cg(ib, CGState.DONE, 1)


@ti.func
def cg_iteration(fb: ti.template(), ib: ti.template(), serial: ti.template()):
    """One PCG iteration; once done, alpha = 0 leaves the solution unchanged."""
    apply_hessian(fb, ib, Slot.CP, Slot.CQ, True, serial=serial)
    dot_nodes(fb, ib, Slot.CP, Slot.CQ, Scalar.PQ, serial=serial)
    alpha = 0.0
    if get_cg(ib, CGState.DONE) == 0:
        if get_sc(fb, ib, Scalar.PQ) <= 0.0:
            set_cg(ib, CGState.NEGCURV, 1)
            set_cg(ib, CGState.DONE, 1)
        else:
            alpha = get_sc(fb, ib, Scalar.RZ) / get_sc(fb, ib, Scalar.PQ)
    ti.loop_config(serialize=serial)
    for i in range(ib[Slot.N]):
        set_v(fb, ib, Slot.CX, i, get_v(fb, ib, Slot.CX, i) + alpha * get_v(fb, ib, Slot.CP, i))
        r = get_v(fb, ib, Slot.CR, i) - alpha * get_v(fb, ib, Slot.CQ, i)
        set_v(fb, ib, Slot.CR, i, r)
        set_v(fb, ib, Slot.CZ, i, get_m2(fb, ib, Slot.MINV, i) @ r)
    dot_nodes(fb, ib, Slot.CR, Slot.CZ, Scalar.S1, serial=serial)
    dot_nodes(fb, ib, Slot.CR, Slot.CR, Scalar.RR, serial=serial)
    beta = 0.0
    if get_cg(ib, CGState.DONE) == 0:
        set_cg(ib, CGState.ITERS, get_cg(ib, CGState.ITERS) + 1)
        if get_sc(fb, ib, Scalar.RR) <= get_sc(fb, ib, Scalar.TOL2):
            set_cg(ib, CGState.DONE, 1)
        beta = get_sc(fb, ib, Scalar.S1) / get_sc(fb, ib, Scalar.RZ)
        set_sc(fb, ib, Scalar.RZ, get_sc(fb, ib, Scalar.S1))
    ti.loop_config(serialize=serial)
    for i in range(ib[Slot.N]):
        set_v(fb, ib, Slot.CP, i, get_v(fb, ib, Slot.CZ, i) + beta * get_v(fb, ib, Slot.CP, i))


@kernel
def k_cg_begin(fb: F64, ib: I32, warm: ti.i32, tol: ti.f64, serial: ti.template()) -> ti.i32:
    cg_begin(fb, ib, warm, tol, serial)
    return get_cg(ib, CGState.DONE)


@kernel
def k_cg_run(fb: F64, ib: I32, iterations: ti.i32) -> ti.i32:
    """A whole PCG solve in one launch (serialized models)."""
    ti.loop_config(serialize=True)
    for _ in range(iterations):
        if get_cg(ib, CGState.DONE) == 0:
            cg_iteration(fb, ib, True)
    return get_cg(ib, CGState.DONE)


@kernel
def k_cg_step(fb: F64, ib: I32):
    """One PCG iteration with parallel loops."""
    cg_iteration(fb, ib, False)


@kernel
def k_cg_done(ib: I32) -> ti.i32:
    return get_cg(ib, CGState.DONE)


# PCG driven from the host, for a preconditioner applied there (a factorization):
# three launches per iteration, the residual going out and the preconditioned one in.
@kernel
def k_pcg_begin(fb: F64, ib: I32, warm: ti.i32, r_out: NDARRAY, serial: ti.template()) -> vec2:
    """CR = CB - H CX0 (copied to r_out as 2n values); returns (|CB|^2, |CR|^2)."""
    cg_residual(fb, ib, warm, serial)
    ti.loop_config(serialize=serial)
    for i in range(ib[Slot.N]):
        r = get_v(fb, ib, Slot.CR, i)
        r_out[2 * i], r_out[2 * i + 1] = r[0], r[1]
    return vec2(get_sc(fb, ib, Scalar.BB), get_sc(fb, ib, Scalar.RR))


@kernel
def k_pcg_matvec(fb: F64, ib: I32, serial: ti.template()) -> ti.f64:
    """CQ = H CP on the free DOFs; returns CP . CQ."""
    apply_hessian(fb, ib, Slot.CP, Slot.CQ, True, serial=serial)
    dot_nodes(fb, ib, Slot.CP, Slot.CQ, Scalar.PQ, serial=serial)
    return get_sc(fb, ib, Scalar.PQ)


@kernel
def k_pcg_update(fb: F64, ib: I32, alpha: ti.f64, r_out: NDARRAY, serial: ti.template()) -> ti.f64:
    """CX += alpha CP, CR -= alpha CQ (copied to r_out); returns |CR|^2."""
    ti.loop_config(serialize=serial)
    for i in range(ib[Slot.N]):
        set_v(fb, ib, Slot.CX, i, get_v(fb, ib, Slot.CX, i) + alpha * get_v(fb, ib, Slot.CP, i))
        r = get_v(fb, ib, Slot.CR, i) - alpha * get_v(fb, ib, Slot.CQ, i)
        set_v(fb, ib, Slot.CR, i, r)
        r_out[2 * i], r_out[2 * i + 1] = r[0], r[1]
    dot_nodes(fb, ib, Slot.CR, Slot.CR, Scalar.RR, serial=serial)
    return get_sc(fb, ib, Scalar.RR)


@kernel
def k_pcg_direction(fb: F64, ib: I32, z_in: NDARRAY, beta: ti.f64, serial: ti.template()):
    """CP = z + beta CP with z the preconditioned residual (masked)."""
    ti.loop_config(serialize=serial)
    for i in range(ib[Slot.N]):
        z = vec2(z_in[2 * i], z_in[2 * i + 1]) * get_v(fb, ib, Slot.MASK, i)
        set_v(fb, ib, Slot.CP, i, z + beta * get_v(fb, ib, Slot.CP, i))



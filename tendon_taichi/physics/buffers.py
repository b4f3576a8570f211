"""Access to a model's two flat buffers from Taichi code: typed reads and writes
of the arrays of :mod:`.layout` (``get_v(fb, ib, Slot.X, i)`` is node i's
position), deterministic reductions over fixed blocks, and the copy kernels
that move arrays between the buffers and numpy."""

from .energies import mat2, mat4
from .launch import kernel
from .layout import BLOCKS, CGState, Scalar, Slot
from .runtime import ti

vec2 = ti.types.vector(2, ti.f64)
#: the two buffers as kernel arguments
F64 = ti.types.ndarray(dtype=ti.f64, ndim=1)
I32 = ti.types.ndarray(dtype=ti.i32, ndim=1)
#: a host f64 vector as a kernel argument
NDARRAY = ti.types.ndarray(dtype=ti.f64, ndim=1)


@ti.func
def get_v(fb: ti.template(), ib: ti.template(), slot, i) -> vec2:
    o = ib[slot] + 2 * i
    return vec2(fb[o], fb[o + 1])


@ti.func
def set_v(fb: ti.template(), ib: ti.template(), slot, i, v: vec2):
    o = ib[slot] + 2 * i
    fb[o] = v[0]
    fb[o + 1] = v[1]


@ti.func
def get_m2(fb: ti.template(), ib: ti.template(), slot, i) -> mat2:
    o = ib[slot] + 4 * i
    return mat2([[fb[o], fb[o + 1]], [fb[o + 2], fb[o + 3]]])


@ti.func
def set_m2(fb: ti.template(), ib: ti.template(), slot, i, A: mat2):
    o = ib[slot] + 4 * i
    fb[o], fb[o + 1], fb[o + 2], fb[o + 3] = A[0, 0], A[0, 1], A[1, 0], A[1, 1]


@ti.func
def get_m4(fb: ti.template(), ib: ti.template(), slot, i) -> mat4:
    o = ib[slot] + 16 * i
    A = mat4(0.0)
    for r, c in ti.static(ti.ndrange(4, 4)):
        A[r, c] = fb[o + 4 * r + c]
    return A


@ti.func
def set_m4(fb: ti.template(), ib: ti.template(), slot, i, A: mat4):
    o = ib[slot] + 16 * i
    for r, c in ti.static(ti.ndrange(4, 4)):
        fb[o + 4 * r + c] = A[r, c]


@ti.func
def get_f(fb: ti.template(), ib: ti.template(), slot, i) -> ti.f64:
    return fb[ib[slot] + i]


@ti.func
def set_f(fb: ti.template(), ib: ti.template(), slot, i, v: ti.f64):
    fb[ib[slot] + i] = v


@ti.func
def get_sc(fb: ti.template(), ib: ti.template(), k) -> ti.f64:
    return fb[ib[Slot.SCALARS] + k]


@ti.func
def set_sc(fb: ti.template(), ib: ti.template(), k, v: ti.f64):
    fb[ib[Slot.SCALARS] + k] = v


@ti.func
def get_cg(ib: ti.template(), k) -> ti.i32:
    return ib[ib[Slot.CG_STATE] + k]


@ti.func
def set_cg(ib: ti.template(), k, v: ti.i32):
    ib[ib[Slot.CG_STATE] + k] = v


@ti.func
def reduce_blocks(fb: ti.template(), ib: ti.template(), count, term: ti.template(), a, b, out,
            serial: ti.template()):
    """scalars[out] = sum of term(fb, ib, a, b, i) for i in [0, count): fixed blocks summed
    in a fixed order, so the result does not depend on threads."""
    chunk = (count + BLOCKS - 1) // BLOCKS
    op = ib[Slot.PARTIAL]
    ti.loop_config(serialize=serial)
    for blk in range(BLOCKS):
        acc = 0.0
        for i in range(blk * chunk, ti.min((blk + 1) * chunk, count)):
            acc += term(fb, ib, a, b, i)
        fb[op + blk] = acc
    total = 0.0
    for blk in ti.static(range(BLOCKS)):
        total += fb[op + blk]
    set_sc(fb, ib, out, total)


@ti.func
def _node_dot(fb: ti.template(), ib: ti.template(), aslot, bslot, i) -> ti.f64:
    return get_v(fb, ib, aslot, i).dot(get_v(fb, ib, bslot, i))


@ti.func
def _entry(fb: ti.template(), ib: ti.template(), slot, unused, i) -> ti.f64:
    return get_f(fb, ib, slot, i)


@ti.func
def dot_nodes(fb: ti.template(), ib: ti.template(), aslot, bslot, out, serial: ti.template()):
    """scalars[out] = sum_i a_i . b_i over nodes."""
    reduce_blocks(fb, ib, ib[Slot.N], _node_dot, aslot, b=bslot, out=out, serial=serial)


@ti.func
def sum_array(fb: ti.template(), ib: ti.template(), slot, count, out, serial: ti.template()):
    """scalars[out] = sum of the f64 array at ``slot`` over [0, count)."""
    reduce_blocks(fb, ib, count, _entry, slot, b=0, out=out, serial=serial)


# ---------------------------------------------------------------- copies between the buffers and numpy
@kernel
def k_copy_nodes(fb: F64, ib: I32, src: ti.i32, dst: ti.i32, serial: ti.template()):
    ti.loop_config(serialize=serial)
    for i in range(ib[Slot.N]):
        set_v(fb, ib, dst, i, get_v(fb, ib, src, i))


@kernel
def k_read(fb: F64, start: ti.i32, out: ti.types.ndarray(dtype=ti.f64, ndim=1)):
    ti.loop_config(serialize=True)
    for k in range(out.shape[0]):
        out[k] = fb[start + k]


@kernel
def k_write(fb: F64, start: ti.i32, src: ti.types.ndarray(dtype=ti.f64, ndim=1)):
    ti.loop_config(serialize=True)
    for k in range(src.shape[0]):
        fb[start + k] = src[k]


@kernel
def k_write_int(ib: I32, start: ti.i32, src: ti.types.ndarray(dtype=ti.i32, ndim=1)):
    ti.loop_config(serialize=True)
    for k in range(src.shape[0]):
        ib[start + k] = src[k]


@kernel
def k_read_ranges(fb: F64, ranges: ti.types.ndarray(dtype=ti.i32, ndim=2),
                   out: ti.types.ndarray(dtype=ti.f64, ndim=1)):
    """out[dst:dst+len] = fb[start:start+len] for each row (start, len, dst)."""
    ti.loop_config(serialize=True)
    for r in range(ranges.shape[0]):
        start, length, dst = ranges[r, 0], ranges[r, 1], ranges[r, 2]
        for k in range(length):
            out[dst + k] = fb[start + k]


@kernel
def k_write_ranges(fb: F64, ranges: ti.types.ndarray(dtype=ti.i32, ndim=2),
                   src: ti.types.ndarray(dtype=ti.f64, ndim=1)):
    """fb[start:start+len] = src[at:at+len] for each row (start, len, at)."""
    ti.loop_config(serialize=True)
    for r in range(ranges.shape[0]):
        start, length, at = ranges[r, 0], ranges[r, 1], ranges[r, 2]
        for k in range(length):
            fb[start + k] = src[at + k]


@kernel
def k_read_int(ib: I32, start: ti.i32) -> ti.i32:
    return ib[start]


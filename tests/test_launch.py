"""The kernel launcher (tendon_taichi/physics/launch.py): after a kernel's first
launch of a kind of arguments through Taichi, launches set the arguments
directly and reuse the compiled kernel. The same kernels give the same numbers
either way - Taichi arrays, numpy arrays, integers, floats, templates, scalar
and vector returns -, a kind not seen yet goes through Taichi again, and
Taichi's own errors are kept. On the CPU a model's buffers are read and
written through numpy views of their memory, with no launch at all: the same
numbers as the copy kernels that other backends use."""

import numpy as np
import pytest

from tendon_taichi.physics import runtime
from tendon_taichi.physics.runtime import ti

runtime.ensure_init()

from tendon_taichi.physics.launch import FastKernel, kernel  # noqa: E402


def _scaled_sum(fb: ti.types.ndarray(dtype=ti.f64, ndim=1), start: ti.i32, scale: ti.f64,
                out: ti.types.ndarray(dtype=ti.f64, ndim=1), serial: ti.template()) -> ti.types.vector(2, ti.f64):
    s = 0.0
    ti.loop_config(serialize=serial)
    for k in range(out.shape[0]):
        out[k] = scale * fb[start + k]
        s += out[k]
    return ti.Vector([s, out[0]])


def _total(fb: ti.types.ndarray(dtype=ti.f64, ndim=1), n: ti.i32) -> ti.f64:
    s = 0.0
    ti.loop_config(serialize=True)
    for k in range(n):
        s += fb[k]
    return s


fast_scaled, plain_scaled = kernel(_scaled_sum), ti.kernel(_scaled_sum)
fast_total, plain_total = kernel(_total), ti.kernel(_total)


@pytest.fixture(scope="module")
def fb():
    a = ti.ndarray(ti.f64, 64)
    a.from_numpy(np.sin(np.arange(64.0)))
    return a


def test_the_launcher_gives_taichis_numbers(fb):
    assert isinstance(fast_scaled, FastKernel) and fast_scaled.fast
    for serial in (True, False, True):
        for start, scale in ((0, 1.0), (5, -2.5), (40, 3)):
            a, b = np.zeros(16), np.zeros(16)
            got = fast_scaled(fb, start, scale, a, serial)
            want = plain_scaled(fb, start, scale, b, serial)
            assert np.array_equal(a, b) and np.array_equal(np.asarray(got), np.asarray(want))
    assert set(k[-1] for k in fast_scaled.compiled) == {True, False}  # one compiled kernel per template value
    for n in (1, 17, 64):
        assert fast_total(fb, n) == plain_total(fb, n) == pytest.approx(np.sin(np.arange(n)).sum(), abs=1e-12)


def test_a_kind_not_seen_goes_through_taichi(fb):
    for bad in (np.zeros(32)[::2], np.zeros(16, dtype=np.int32)):  # strided; int32 where f64 is declared
        with pytest.raises(Exception) as fast_error:  # Taichi's error, not a wrong read
            fast_scaled(fb, 0, 1.0, bad, True)
        with pytest.raises(Exception) as plain_error:
            plain_scaled(fb, 0, 1.0, bad, True)
        assert type(fast_error.value) is type(plain_error.value)
    a = np.zeros(16)
    fast_scaled(fb, 1, 1.0, a, True)
    assert np.array_equal(a, np.sin(np.arange(1.0, 17.0)))


def test_host_views_move_the_numbers_the_copy_kernels_do():
    from tendon_taichi import Model, build_problem, load_scene

    p = build_problem(load_scene("t_shape"), 1)
    views, kernels = (Model.from_problem(p) for _ in range(2))
    assert views._fb_host is not None and views._ib_host is not None  # the CPU backend
    kernels._fb_host = kernels._ib_host = None  # what a GPU backend does
    rng = np.random.default_rng(3)
    x = p.mesh.nodes + 1e-3 * p.size * rng.standard_normal(p.mesh.nodes.shape)
    ac = 0.05 * p.fiber_cables.a0 * rng.random(views.C)
    for m in (views, kernels):
        m.set_positions(x)
        m.write_many([("RHO", np.linspace(0.5, 1.0, m.C)), ("SEG_WT", np.linspace(1.0, 0.9, m.S))])
        m.write_int("PT_TRI", m.cables.points.tri[::-1].copy())
        m.write_int("PT_TRI", m.cables.points.tri)
        m.set_contraction(ac)
    assert np.array_equal(views.positions(), kernels.positions())
    assert views.read_int("PT_TRI", 5) == kernels.read_int("PT_TRI", 5) == p.fiber_cables.points.tri[5]
    for a, b in zip(views.read_many([("RHO", views.C), ("SEG_WT", views.S), ("X", 8)]),
                    kernels.read_many([("RHO", views.C), ("SEG_WT", views.S), ("X", 8)])):
        assert np.array_equal(a, b)
    assert views.energy_and_min_det() == kernels.energy_and_min_det()
    assert views.gradient_norm2() == kernels.gradient_norm2()
    assert np.array_equal(views.last_gradient, kernels.last_gradient)
    views.read("X", 4)[:] = 0.0  # a read is a copy, never the buffer itself
    assert np.array_equal(views.positions(), kernels.positions())


def test_a_kernel_that_does_not_compile_names_its_file_line_and_code():
    """Taichi's source positions, described plainly (runtime._plain_source_positions),
    still point at the offending line."""
    def broken(n: ti.i32) -> ti.i32:
        return n + not_defined  # noqa: F821

    with pytest.raises(Exception) as err:
        ti.kernel(broken)(1)
    text = str(err.value)
    assert "test_launch.py" in text and "return n + not_defined" in text and "line" in text

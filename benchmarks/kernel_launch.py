"""What launching one of the package's Taichi kernels costs beside its work.

Usage: python benchmarks/kernel_launch.py [--launches N]

A kernel of one loop over 16 entries (a scaled copy and its sum), launched N
times (default 20000) each way, the median of five rounds, in microseconds per
launch: ``through Taichi`` (``ti.kernel``'s own call path, ``FastKernel.wrapped``)
and ``through the launcher`` (:func:`tendon_taichi.physics.launch.kernel`, which
reuses the compiled kernel and sets the arguments directly), both with the loop
serialized - their difference is the Python Taichi spends per launch, their
ratio what the launcher saves -, then ``parallel``: through the launcher with
the loop parallel, whose difference from the serialized one is what dispatching
a parallel loop costs. tendon_taichi/physics/launch.py quotes the first two,
tendon_taichi/physics/forces.py and tendon_taichi/physics/runtime.py the last.
"""

import argparse
import statistics
import sys
import time

import numpy as np

from tendon_taichi.physics import runtime
from tendon_taichi.physics.launch import kernel
from tendon_taichi.physics.runtime import ti


def _copy_sum(a: ti.types.ndarray(dtype=ti.f64, ndim=1), out: ti.types.ndarray(dtype=ti.f64, ndim=1),
              serial: ti.template()) -> ti.f64:
    s = 0.0
    ti.loop_config(serialize=serial)
    for k in range(out.shape[0]):
        out[k] = 2.0 * a[k]
        s += out[k]
    return s


copy_sum = kernel(_copy_sum)


def per_call_us(fn, launches: int, rounds: int = 5) -> float:
    """The median over ``rounds`` of the mean time of ``fn()`` over ``launches`` calls (us)."""
    fn()  # compiles
    times = []
    for _ in range(rounds):
        t = time.perf_counter()
        for _ in range(launches):
            fn()
        times.append((time.perf_counter() - t) / launches)
    return 1e6 * statistics.median(times)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--launches", type=int, default=20000)
    args = ap.parse_args(argv)
    runtime.ensure_init()
    n, a, out = args.launches, np.ones(16), np.zeros(16)
    taichi = per_call_us(lambda: copy_sum.wrapped(a, out, True), n)
    launcher = per_call_us(lambda: copy_sum(a, out, True), n)
    parallel = per_call_us(lambda: copy_sum(a, out, False), n)
    print(f"through Taichi: {taichi:.1f} us, through the launcher: {launcher:.1f} us "
          f"(Taichi's Python {taichi - launcher:.1f} us, {taichi / launcher:.1f}x)")
    print(f"parallel: {parallel:.1f} us (dispatching the parallel loop {parallel - launcher:.1f} us)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

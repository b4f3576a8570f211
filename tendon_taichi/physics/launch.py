"""Kernel launches with less Python per call.

Our kernels are small and launched hundreds of thousands of times by one
design (``design t_shape`` at level 1: about 680 000 launches), and Taichi's
own ``Kernel.__call__`` spends 40-70 us of Python per launch on the CPU - on
argument processing, the template mapping and checks that give the same answer
every time for a given kernel and kind of arguments. :func:`kernel` is
``ti.kernel`` whose launches, after the first of each kind through Taichi
(which compiles and checks it), reuse that compiled kernel and set the
arguments directly: 4x less per launch (both figures: benchmarks/kernel_launch.py),
the same compiled code, the same numbers. A call whose arguments are of a kind not seen yet (another template
value, another array dtype or rank, a non-contiguous numpy array, another
Taichi program) goes through Taichi.
"""

from __future__ import annotations

import numpy as np

from .runtime import ti

_TEMPLATE, _ARRAY, _INT, _FLOAT = range(4)


def kernel(fn):
    """``ti.kernel`` launched by :class:`FastKernel`."""
    return FastKernel(ti.kernel(fn))


def _kind(annotation) -> int | None:
    """How an argument of this annotation is passed (None: only Taichi may)."""
    from taichi.lang.kernel_impl import template
    from taichi.types import ndarray_type, primitive_types

    if isinstance(annotation, template):
        return _TEMPLATE
    if isinstance(annotation, ndarray_type.NdarrayType):
        return _ARRAY
    if any(annotation is t for t in (ti.i8, ti.i16, ti.i32, ti.i64)):  # signed (unsigned: Taichi's way)
        return _INT
    if id(annotation) in primitive_types.real_type_ids:
        return _FLOAT
    return None


class FastKernel:
    """A Taichi kernel (``wrapped``, what ``ti.kernel`` returned) whose launches
    reuse the compiled kernel of their kind of arguments (module docstring)."""

    def __init__(self, wrapped):
        from taichi.lang import impl
        from taichi.lang.enums import AutodiffMode

        self.wrapped = wrapped
        self.primal = wrapped._primal
        self.__name__ = getattr(self.primal.func, "__name__", "kernel")
        self.__doc__ = self.primal.func.__doc__
        self._impl = impl
        self.kinds = [_kind(a.annotation) for a in self.primal.arguments]
        self.fast = None not in self.kinds and self.primal.autodiff_mode == AutodiffMode.NONE
        #: per kind of arguments: (the C++ kernel, its compiled data, the program)
        self.compiled: dict[tuple, tuple] = {}
        self.readers = [_reader(rt, (i,)) for i, rt in enumerate(self.primal.return_type or ())]

    def _key(self, args: tuple) -> tuple | None:
        """The kind of these arguments (None: not one this launcher passes)."""
        if len(args) != len(self.kinds):
            return None
        key = []
        for a, kind in zip(args, self.kinds):
            if kind == _TEMPLATE:
                key.append(a)
            elif kind == _ARRAY:
                if isinstance(a, np.ndarray):
                    if not a.flags.c_contiguous:
                        return None
                    key.append((a.dtype.str, a.ndim))
                elif getattr(a, "grad", True) is None and hasattr(a, "arr"):
                    key.append((a.dtype, len(a.shape)))
                else:
                    return None
            else:
                key.append(type(a))
        return tuple(key)

    def __call__(self, *args):
        key = self._key(args) if self.fast else None
        prog = self._impl.get_runtime().prog
        entry = None if key is None else self.compiled.get(key)
        if entry is None or entry[2] is not prog:
            out = self.wrapped(*args)  # Taichi compiles, checks and launches
            if key is not None:
                t_kernel = self.primal.compiled_kernels[self.primal.ensure_compiled(*args)]
                self.compiled[key] = (t_kernel, prog.compile_kernel(prog.config(), prog.get_device_caps(), t_kernel),
                                      prog)
            return out
        t_kernel, data, _ = entry
        ctx = t_kernel.make_launch_context()
        j = 0
        for a, kind in zip(args, self.kinds):
            if kind == _TEMPLATE:
                continue
            if kind == _ARRAY:
                if isinstance(a, np.ndarray):
                    ctx.set_arg_external_array_with_shape((j,), int(a.ctypes.data), a.nbytes, a.shape, 0)
                else:
                    ctx.set_arg_ndarray((j,), a.arr)
            elif kind == _INT:
                ctx.set_arg_int((j,), int(a))
            else:
                ctx.set_arg_float((j,), float(a))
            j += 1
        prog.launch_kernel(data, ctx)
        returns = self.primal.return_type
        if returns is None and not self.primal.has_print:
            return None
        ti.sync()
        if returns is None:
            return None
        out = [read(ctx) if read else self.primal.construct_kernel_ret(ctx, rt, (i,))
               for i, (rt, read) in enumerate(zip(returns, self.readers))]
        return out[0] if len(out) == 1 else out


def _reader(ret_type, index: tuple):
    """A function reading a returned value of ``ret_type`` at ``index`` from a launch
    context - a number, or a vector's entries as a tuple of numbers - in place of
    the ``ti.Vector`` Taichi makes for them; None: Taichi's way."""
    from taichi.lang.matrix import VectorType
    from taichi.types import primitive_types

    kind = _kind(ret_type)  # a signed integer or a real number, as an argument would be
    if kind == _INT:
        return lambda ctx: ctx.get_struct_ret_int(index)
    if kind == _FLOAT:
        return lambda ctx: ctx.get_struct_ret_float(index)
    if isinstance(ret_type, VectorType) and ret_type.dtype in primitive_types.real_types:
        entries = [index + (j,) for j in range(ret_type.m * ret_type.n)]
        return lambda ctx: tuple(ctx.get_struct_ret_float(e) for e in entries)
    return None

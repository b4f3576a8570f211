"""Probes: named points of the package that benchmarks time and watch without
patching it.

A function defined with ``@probe("factor")`` calls itself while nothing
listens to its probe: all it costs then is one more Python call and one look-up
in an empty dictionary, against the tens of microseconds and more of the parts
probed. Benchmarks listen for the duration of a ``with`` block:

* :func:`timers` sums the wall time (s) and the calls of named probes. It only
  times: every result is the same to the bit as without it.
* :func:`around` runs ``wrapper(call, *args, **kwargs)`` in place of each call of
  a probe, where ``call`` is the probed function (or the next wrapper): to keep
  a call's arguments, count calls, or do the same work another way beside or
  instead of the package's. What the wrapper returns is the call's result.

:data:`PROBES` lists the probes of the modules imported so far. The package
declares: ``factor`` and ``solves`` (the sparse Cholesky's numerical
factorizations and triangular solves, ``LDL`` and ``PardisoLDL``), ``assembly``
(``Model.hessian_sums``), ``prepare`` (``Model.prepare_hessian``), ``check``
(the product that checks a direct solve), ``factorization`` (a direct
``Factorization`` made), ``indefinite`` (the pattern's PARDISO indefinite
LDL^T; None makes SuperLU factorize), ``pardiso`` (whether MKL PARDISO loaded),
``optimize_routes``, ``RouteObjective.value``, ``PoseSolve.adjoint``,
``solve_realizable``, ``SoftIK.__init__`` and the soft IK's ``SoftIK.configure``,
``SoftIK.restart``, ``SoftIK.warm_start``, ``SoftIK.settle`` and
``SoftIK.evaluate``, and the front's ``screened`` and ``continued`` extensions.
"""

from __future__ import annotations

import time
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from functools import partial, wraps
from typing import Callable, Iterator

#: every probe declared so far: its name -> the functions it wraps (module.qualname)
PROBES: dict[str, set[str]] = {}
_listening: dict[str, list[Callable]] = {}  # per probe listened to: its wrappers, the outermost last


def probe(name: str | None = None) -> Callable[[Callable], Callable]:
    """Decorator: the function as the probe ``name`` (default: its qualified name,
    ``SoftIK.evaluate``). Several functions may share a name (one per class of a
    kind: ``LDL.factor`` and ``PardisoLDL.factor`` are both ``factor``)."""
    def declare(fn: Callable) -> Callable:
        key = name or fn.__qualname__
        PROBES.setdefault(key, set()).add(f"{fn.__module__}.{fn.__qualname__}")

        @wraps(fn)
        def probed(*args, **kwargs):
            wrappers = _listening.get(key)
            if not wrappers:
                return fn(*args, **kwargs)
            call = fn
            for wrapper in wrappers:
                call = partial(wrapper, call)
            return call(*args, **kwargs)
        probed.probe = key
        return probed
    return declare


@contextmanager
def around(name: str, wrapper: Callable) -> Iterator[None]:
    """Within, every call of the probe ``name`` runs ``wrapper(call, *args,
    **kwargs)`` (module docstring); a wrapper added later runs outside one added
    before. Raises KeyError for a probe no imported module declares."""
    if name not in PROBES:
        raise KeyError(f"no probe {name!r} (declared: {', '.join(sorted(PROBES))}); import its module first")
    _listening.setdefault(name, []).append(wrapper)
    try:
        yield
    finally:
        wrappers = _listening[name]
        del wrappers[max(i for i, w in enumerate(wrappers) if w is wrapper)]
        if not wrappers:
            del _listening[name]


@dataclass
class Timer:
    """What :func:`timers` sums for one probe: wall ``seconds`` and ``calls``."""

    seconds: float = 0.0
    calls: int = 0

    def wrapper(self, call: Callable, *args, **kwargs):
        """:func:`around`'s wrapper that times each call into this timer."""
        t0 = time.perf_counter()
        try:
            return call(*args, **kwargs)
        finally:
            self.seconds += time.perf_counter() - t0
            self.calls += 1


@contextmanager
def timers(*names: str) -> Iterator[dict[str, Timer]]:
    """Within, each call of the probes ``names`` timed: yields name -> :class:`Timer`.
    A call inside another probe timed counts in both."""
    clock = {name: Timer() for name in names}
    with ExitStack() as stack:
        for name, timer in clock.items():
            stack.enter_context(around(name, timer.wrapper))
        yield clock

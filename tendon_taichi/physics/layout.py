"""The buffer layout of a model: every array of a model lives in one flat f64
buffer ``fb`` and one flat i32 buffer ``ib``, allocated once per model.

``ib`` starts with a header: entry ``Slot.NAME`` holds a size (``Slot.N`` ...
``Slot.SINGLE``) or the offset of array ``NAME`` (in ``ib`` for the integer
arrays, in ``fb`` for the f64 ones). Kernels take ``(fb, ib)`` and a slot
number, so they compile once per process and serve every model (a new mesh, a
sweep case, a realizable robot) without recompiling.

Each array's length is counted in units of the model's sizes: nodes ``n``,
elements (triangles) ``m``, cable segments ``S``, cables ``C``, embedded
points ``P`` and a fixed count (``fixed``). Vectors per node take 2 entries
(x, y), 2x2 blocks 4, element tangents 16.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: blocks of every deterministic reduction (sums run over fixed blocks, in a fixed order)
BLOCKS = 32

_UNITS = ("node", "element", "segment", "cable", "point", "fixed")
INT_ARRAYS: list[tuple[str, tuple[int, ...]]] = []
F64_ARRAYS: list[tuple[str, tuple[int, ...]]] = []
_slots: list[str] = ["N", "M", "S", "C", "P", "SINGLE"]


def _declare(table: list, name: str, per: dict[str, int]) -> int:
    unknown = set(per) - set(_UNITS)
    if unknown:
        raise ValueError(f"unknown units {unknown}")
    table.append((name, tuple(per.get(u, 0) for u in _UNITS)))
    _slots.append(name)
    return len(_slots) - 1


def _int(name: str, **per: int) -> int:
    """An i32 array of ``sum(per[u] * size(u))`` entries; returns its slot."""
    return _declare(INT_ARRAYS, name, per)


def _f64(name: str, **per: int) -> int:
    """An f64 array of ``sum(per[u] * size(u))`` entries; returns its slot."""
    return _declare(F64_ARRAYS, name, per)


class Slot:
    """Header entries of ``ib``: the sizes, then the offset of each array."""

    # sizes: nodes, elements, cable segments, cables, embedded points, 1 if every cable is one segment
    N, M, S, C, P, SINGLE = range(6)
    # integer arrays
    TRI = _int("TRI", element=3)                 # triangle corners
    NE_START = _int("NE_START", node=1, fixed=1)  # node -> element-corner CSR starts
    NE = _int("NE", element=3)                   # entries 3 e + corner
    NS_START = _int("NS_START", node=1, fixed=1)  # node -> segment CSR starts
    NS = _int("NS", segment=6)                   # segment ids
    PT_TRI = _int("PT_TRI", point=1)             # triangle of each embedded point
    SEG = _int("SEG", segment=3)                 # per segment: point a, point b, cable
    CAB_START = _int("CAB_START", cable=1, fixed=1)  # cable -> segment starts
    CG_STATE = _int("CG_STATE", fixed=4)         # see CGState
    # f64 arrays: node vectors
    X0 = _f64("X0", node=2)        # rest positions
    X = _f64("X", node=2)          # positions
    XT = _f64("XT", node=2)        # trial positions of the line search
    DX = _f64("DX", node=2)        # Newton direction
    G = _f64("G", node=2)          # dE/dx
    MASK = _f64("MASK", node=2)    # 1 on free DOFs, 0 on clamped ones
    FEXT = _f64("FEXT", node=2)    # external (gravity) forces
    VIN = _f64("VIN", node=2)      # input of a product
    VOUT = _f64("VOUT", node=2)    # its output
    CB = _f64("CB", node=2)        # CG: right-hand side
    CX = _f64("CX", node=2)        # CG: solution
    CR = _f64("CR", node=2)        # CG: residual
    CZ = _f64("CZ", node=2)        # CG: preconditioned residual
    CP = _f64("CP", node=2)        # CG: search direction
    CQ = _f64("CQ", node=2)        # CG: H times the search direction
    MINV = _f64("MINV", node=4)    # block-Jacobi preconditioner, 2x2 per node
    # per element
    BM = _f64("BM", element=4)     # D_m^-1
    VOL = _f64("VOL", element=1)   # h A
    D = _f64("D", element=16)      # dP/dF (exact or projected)
    EV = _f64("EV", element=6)     # nodal vectors (scratch)
    EE = _f64("EE", element=1)     # energy
    # per cable segment and embedded point
    NS_COEF = _f64("NS_COEF", segment=6)  # signed barycentric weight of each node-segment entry
    PT_BARY = _f64("PT_BARY", point=3)    # barycentric weights of the embedded points
    SEG_N = _f64("SEG_N", segment=2)      # unit direction
    SEG_L = _f64("SEG_L", segment=1)      # length
    SEG_DD = _f64("SEG_DD", segment=2)    # change of the segment vector along a direction
    SEG_W = _f64("SEG_W", segment=1)      # n . that change
    SEG_VEC = _f64("SEG_VEC", segment=2)  # per-segment force vector (scratch)
    SEG_WT = _f64("SEG_WT", segment=1)    # capstan weight w_s = exp(-mu Theta_s) (1: frictionless)
    # per cable
    A0 = _f64("A0", cable=1)          # rest length a0, m
    RHO = _f64("RHO", cable=1)        # weighted rest-length factor sum w l0 / sum l0 (1: frictionless)
    AC = _f64("AC", cable=1)          # contraction ac, m
    EA = _f64("EA", cable=1)          # axial stiffness, N
    L = _f64("L", cable=1)            # current length, m
    TAU = _f64("TAU", cable=1)        # tension, N
    KC = _f64("KC", cable=1)          # dtau/dL, N/m
    TAU_AC = _f64("TAU_AC", cable=1)  # dtau/dac, N/m
    CE = _f64("CE", cable=1)          # energy, J
    CW = _f64("CW", cable=1)          # dL/dx . a direction
    CCOEF = _f64("CCOEF", cable=1)    # per-cable weights of a product
    # fixed size
    SCALARS = _f64("SCALARS", fixed=16)      # see Scalar
    PARTIAL = _f64("PARTIAL", fixed=BLOCKS)  # partial sums of a reduction


#: length of the header of ``ib``
HEADER = len(_slots)


class Scalar:
    """Entries of the ``SCALARS`` array: material constants, reduction outputs
    (``S0``-``S2``), the smallest det F (``JMIN``) and the CG scalars."""

    MU, LAM, EPS, FLOOR, S0, S1, S2, JMIN, RZ, RR, PQ, BB, TOL2 = range(13)


class CGState:
    """Entries of the ``CG_STATE`` array: iterations run, done, met negative curvature."""

    ITERS, DONE, NEGCURV = range(3)


@dataclass
class HostBuffers:
    """The two buffers on the host before upload: ``fb`` (f64), ``ib`` (int64, made
    i32 on upload) and each array's ``offset`` by name."""

    fb: np.ndarray
    ib: np.ndarray
    offset: dict[str, int]

    def put_int(self, name: str, values) -> None:
        a = np.asarray(values, dtype=np.int64).ravel()
        self.ib[self.offset[name]:self.offset[name] + len(a)] = a

    def put_f64(self, name: str, values) -> None:
        a = np.asarray(values, dtype=np.float64).ravel()
        self.fb[self.offset[name]:self.offset[name] + len(a)] = a


def allocate(n: int, m: int, S: int, C: int, P: int, single: bool) -> HostBuffers:
    """Zeroed host buffers for a model of these sizes, with the header filled in."""
    sizes = np.array([n, m, S, C, P, 1])
    ib_len, fb_len, offset = HEADER, 0, {}
    header = np.zeros(HEADER, dtype=np.int64)
    header[:6] = [n, m, S, C, P, int(single)]
    for name, unit in INT_ARRAYS:
        header[getattr(Slot, name)] = offset[name] = ib_len
        ib_len += int(np.dot(unit, sizes))
    for name, unit in F64_ARRAYS:
        header[getattr(Slot, name)] = offset[name] = fb_len
        fb_len += int(np.dot(unit, sizes))
    if ib_len > np.iinfo(np.int32).max or fb_len > np.iinfo(np.int32).max:
        raise ValueError("model too large for 32-bit offsets")
    ib = np.zeros(ib_len, dtype=np.int64)
    ib[:HEADER] = header
    return HostBuffers(np.zeros(fb_len, dtype=np.float64), ib, offset)


def csr(keys: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Row starts (n+1,) and the stable order that sorts ``keys``."""
    order = np.argsort(keys, kind="stable")
    start = np.zeros(n + 1, dtype=np.int64)
    np.add.at(start, keys + 1, 1)
    return np.cumsum(start), order

"""Many right-hand sides through one CHOLMOD call, on the factor cvxopt already holds.

cvxopt's ``cholmod.solve(F, B)`` sends the columns of ``B`` one at a time through
``cholmod_l_solve``, so 48 right-hand sides cost 48 sparse triangular sweeps with level-2 BLAS.
CHOLMOD itself solves a block of columns with one sweep of level-3 BLAS (``dtrsm``/``dgemm`` per
supernode): measured at 33,000 free DOFs, 48 columns in 0.24x the time of the column loop, and
0.19x at 135,000 (``lipgen bench --suite physics``, ``multi_rhs``). This module calls
``cholmod_l_solve`` of the very library cvxopt is linked against (the copy in ``cvxopt.libs``,
already loaded by ``import cvxopt.cholmod``), with the factor taken from cvxopt's capsule; there
is no second factorisation.

The binding depends on two stable C layouts of CHOLMOD (``cholmod_dense``: four ``size_t``, two
pointers, two ``int``; the capsule name cvxopt gives a real lower factor). :func:`dense_solve`
returns ``None`` whenever anything does not look as expected, and
:meth:`lipgen.fem.solver.Factor.check` compares it with the column loop on a known solution before
it is used, so a mismatch falls back to the loop rather than returning wrong numbers.
"""

from __future__ import annotations

import ctypes
import functools
import glob
import logging
import os

import numpy as np

__all__ = ["dense_solve", "library"]

log = logging.getLogger(__name__)

_CAPSULE = b"CHOLMOD FACTOR D L"  # cvxopt's name for a real factor of a lower-stored matrix
_REAL, _DOUBLE = 1, 0  # CHOLMOD_REAL, CHOLMOD_DOUBLE
_COMMON_BYTES = 1 << 16  # cholmod_common is ~3 KB in CHOLMOD 3-5; a generous buffer


class _Dense(ctypes.Structure):
    """``cholmod_dense`` (CHOLMOD 1.x-5.x)."""

    _fields_ = [("nrow", ctypes.c_size_t), ("ncol", ctypes.c_size_t), ("nzmax", ctypes.c_size_t),
                ("d", ctypes.c_size_t), ("x", ctypes.c_void_p), ("z", ctypes.c_void_p),
                ("xtype", ctypes.c_int), ("dtype", ctypes.c_int)]


@functools.lru_cache(maxsize=1)
def library() -> ctypes.CDLL | None:
    """The CHOLMOD shared library cvxopt is linked against, with argument types set, or None."""
    try:
        import cvxopt
        import cvxopt.cholmod  # noqa: F401  (loads the library into the process)
    except ImportError:
        return None
    here = os.path.dirname(cvxopt.__file__)
    found = sorted(glob.glob(os.path.join(here, os.pardir, "cvxopt.libs", "libcholmod*.so*")))
    names = found or ["libcholmod.so", "libcholmod.so.3"]  # a cvxopt built against the system's
    for name in names:
        try:
            lib = ctypes.CDLL(name)
            solve, free, start, finish = (lib.cholmod_l_solve, lib.cholmod_l_free_dense,
                                          lib.cholmod_l_start, lib.cholmod_l_finish)
        except (OSError, AttributeError):
            continue
        solve.restype = ctypes.POINTER(_Dense)
        solve.argtypes = [ctypes.c_int, ctypes.c_void_p, ctypes.POINTER(_Dense), ctypes.c_void_p]
        free.restype = ctypes.c_int
        free.argtypes = [ctypes.POINTER(ctypes.POINTER(_Dense)), ctypes.c_void_p]
        start.restype = finish.restype = ctypes.c_int
        start.argtypes = finish.argtypes = [ctypes.c_void_p]
        log.debug("multi-column CHOLMOD solves through %s", name)
        return lib
    log.debug("no CHOLMOD library found beside cvxopt: multi-column solves go column by column")
    return None


def _factor_pointer(factor) -> int | None:
    """The ``cholmod_factor *`` inside cvxopt's capsule, or None if it is not one."""
    api = ctypes.pythonapi
    api.PyCapsule_IsValid.restype = ctypes.c_int
    api.PyCapsule_IsValid.argtypes = [ctypes.py_object, ctypes.c_char_p]
    if not api.PyCapsule_IsValid(factor, _CAPSULE):
        return None
    api.PyCapsule_GetPointer.restype = ctypes.c_void_p
    api.PyCapsule_GetPointer.argtypes = [ctypes.py_object, ctypes.c_char_p]
    return api.PyCapsule_GetPointer(factor, _CAPSULE)


def dense_solve(factor, B: np.ndarray) -> np.ndarray | None:
    """``A⁻¹ B`` for all columns at once with the CHOLMOD factor of ``A`` held by cvxopt.

    Parameters
    ----------
    factor : PyCapsule
        cvxopt's numeric factor (``cholmod.symbolic`` then ``cholmod.numeric``) of an (N, N)
        real matrix stored lower.
    B : (N, k) float
        Right-hand sides.

    Returns
    -------
    (N, k) float64 or None
        The solutions (Fortran order), or None when the library or the factor is not usable
        (the caller then solves column by column).
    """
    lib = library()
    pointer = _factor_pointer(factor) if lib is not None else None
    if pointer is None:
        return None
    B = np.asfortranarray(B, dtype=np.float64)
    n, k = B.shape
    rhs = _Dense(n, k, n * k, n, B.ctypes.data, None, _REAL, _DOUBLE)
    common = ctypes.create_string_buffer(_COMMON_BYTES)
    lib.cholmod_l_start(common)
    try:
        X = lib.cholmod_l_solve(0, pointer, ctypes.byref(rhs), common)  # sys 0: A x = b
        if not X:
            return None
        try:
            x = X.contents
            if (x.nrow, x.ncol, x.d, x.xtype) != (n, k, n, _REAL) or not x.x:
                return None
            data = ctypes.cast(x.x, ctypes.POINTER(ctypes.c_double))
            return np.ctypeslib.as_array(data, shape=(k, n)).copy().T
        finally:
            lib.cholmod_l_free_dense(ctypes.byref(X), common)
    finally:
        lib.cholmod_l_finish(common)

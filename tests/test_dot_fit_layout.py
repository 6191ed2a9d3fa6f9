"""The dot fit and the corner fit must not depend on where numpy puts its arrays (found by review, det15j).

numpy 1.26 on AVX-512 computes ``np.power`` with SVML, but falls back to libm's ``pow`` (1 ulp
apart) when a conservative overlap check, which overshoots a strided view's end, meets an output
allocated just after the input: ``ps ** 3`` on a column of the parameters then gave tracks that
differed by 1e-8 px from run to run, with the heap layout (argv, environment). Here the two
implementations are forced in turn through an ndarray subclass; the fit must give the same bits.
"""

import math

import numpy as np

from lipgen.recon.dots import _lm_fit

_LIBM_POW = np.frompyfunc(math.pow, 2, 1)


class _PowerPath(np.ndarray):
    """An array whose ``np.power`` calls take libm's path when ``libm`` is set (else numpy's)."""

    libm = False

    def __array_ufunc__(self, ufunc, method, *inputs, **kwargs):
        plain = [x.view(np.ndarray) if isinstance(x, _PowerPath) else x for x in inputs]
        if "out" in kwargs:
            kwargs["out"] = tuple(
                o.view(np.ndarray) if isinstance(o, _PowerPath) else o for o in kwargs["out"]
            )
        if ufunc is np.power and method == "__call__" and _PowerPath.libm and not kwargs:
            a, b = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in plain))
            result = _LIBM_POW(a, b).astype(np.float64)
        else:
            result = getattr(ufunc, method)(*plain, **kwargs)
        floating = isinstance(result, np.ndarray) and result.dtype.kind == "f"
        return result.view(_PowerPath) if floating else result


def _patches(k=12, seed=3):
    rng = np.random.default_rng(seed)
    offs = np.arange(-5.0, 6.0)
    dy, dx = (a.ravel() for a in np.meshgrid(offs, offs, indexing="ij"))
    bg = np.stack([np.ones_like(dx), dx, dy, dx * dx, dx * dy, dy * dy], axis=1)
    u, v = rng.uniform(-0.5, 0.5, (2, k))
    s = rng.uniform(1.0, 1.6, k)
    dot = np.exp(-((dx - u[:, None]) ** 2 + (dy - v[:, None]) ** 2) / (2 * s[:, None] ** 2))
    img = 200.0 - 80.0 * dot + rng.normal(0.0, 2.0, (k, dx.size))
    params = np.column_stack(
        [u + 0.3, v - 0.2, np.full(k, 1.3), np.full(k, 70.0), np.full(k, 200.0), np.zeros((k, 5))]
    )
    return img, bg, dx, dy, params


def test_dot_fit_is_the_same_with_either_power_implementation():
    img, bg, dx, dy, params = _patches()
    fits = []
    for libm in (False, True):
        _PowerPath.libm = libm
        try:
            fits.append(np.asarray(_lm_fit(img, bg, dx, dy, params.view(_PowerPath), 15, 1.3)))
        finally:
            _PowerPath.libm = False
    assert np.isfinite(fits[0]).all()
    assert fits[0].tobytes() == fits[1].tobytes(), np.abs(fits[0] - fits[1]).max()


_LIBM_ATAN2 = np.frompyfunc(math.atan2, 2, 1)


class _StridedTakesLibm:
    """numpy, except that ``arctan2`` on a non-contiguous input is libm's (as numpy's overlap check
    can make it), and numpy's own on contiguous inputs."""

    def __getattr__(self, name):
        return getattr(np, name)

    @staticmethod
    def arctan2(y, x):
        if all(np.asarray(a).flags.c_contiguous for a in (y, x)):
            return np.arctan2(y, x)
        return _LIBM_ATAN2(np.asarray(y, float), np.asarray(x, float)).astype(np.float64)


def test_the_corner_fits_start_is_the_same_with_either_arctan2(monkeypatch):
    # the same hazard in the chessboard corner fit's edge angles (lead's audit after det15j)
    from lipgen.recon import cornerfit

    rng = np.random.default_rng(2)
    rows, cols = 5, 7
    grid = np.stack(np.meshgrid(np.arange(cols) * 23.0, np.arange(rows) * 21.0), axis=-1)
    c0 = (grid.reshape(-1, 2) + rng.normal(0.0, 1.5, (rows * cols, 2))) @ [[0.97, 0.24], [-0.24, 0.97]]
    plain = cornerfit._prepare(c0, (rows, cols), 0.45, 12.0)
    monkeypatch.setattr(cornerfit, "np", _StridedTakesLibm())
    forced = cornerfit._prepare(c0, (rows, cols), 0.45, 12.0)
    assert plain.keys() == forced.keys()
    for key in plain:
        assert np.asarray(plain[key]).tobytes() == np.asarray(forced[key]).tobytes(), key

"""The joint bundle adjustment of a camera-mirror rig: one camera's intrinsics and lens, the
mirror plane and every board's pose, over all corners of both views (scipy least squares).

:mod:`lipgen.recon.calibrate` starts it from OpenCV's single-view calibration.
"""

from __future__ import annotations

import numpy as np


def _project(X: np.ndarray, f: np.ndarray, c: np.ndarray, k: np.ndarray) -> np.ndarray:
    """OpenCV's projection with distortion ``k = (k1, k2, p1, p2)``."""
    xy = X[..., :2] / X[..., 2:]
    x, y = xy[..., 0], xy[..., 1]
    r2 = x * x + y * y
    rad = 1 + r2 * (k[0] + r2 * k[1])
    xd = x * rad + 2 * k[2] * x * y + k[3] * (r2 + 2 * x * x)
    yd = y * rad + k[2] * (r2 + 2 * y * y) + 2 * k[3] * x * y
    return np.stack([xd, yd], -1) * f + c


_DIST_MASK = {"none": np.zeros(4), "radial": np.array([1.0, 1, 0, 0]), "full": np.ones(4)}


def _bundle_adjust(objs, obs, K, dist, poses, n0, d0, distortion):
    """Refine intrinsics, mirror (n, d) and board poses on all corners; returns the fit.

    ``objs[k]`` are image k's board corners; ``distortion`` is "none", "radial" (k1, k2) or
    "full" (k1, k2, p1, p2)."""
    mask = _DIST_MASK[distortion]
    dist = np.asarray(dist, float)[:4] * mask
    from scipy.optimize import least_squares
    from scipy.spatial.transform import Rotation

    u = np.cross(n0, [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(n0, u)
    views = [(k, view, uv) for k, per in enumerate(obs) for view, uv in per.items()]
    index = {k: i for i, k in enumerate(sorted(poses))}
    x0 = np.concatenate([[K[0, 0], K[1, 1], K[0, 2], K[1, 2]], dist, [0.0, 0.0, d0],
                         np.concatenate([np.r_[Rotation.from_matrix(poses[k][0]).as_rotvec(), poses[k][1]]
                                         for k in sorted(poses)])])

    def unpack(x):
        n = n0 + x[8] * u + x[9] * v
        n = n / np.linalg.norm(n)
        b = x[11:].reshape(-1, 6)
        kk = x[4:8] * mask
        return x[0:2], x[2:4], kk, n, x[10], Rotation.from_rotvec(b[:, :3]).as_matrix(), b[:, 3:]

    def residuals(x):
        f, c, kk, n, d, Rb, tb = unpack(x)
        out = []
        for k, view, uv in views:
            X = objs[k] @ Rb[index[k]].T + tb[index[k]]
            if view == "virtual":
                X = X - 2.0 * (X @ n - d)[:, None] * n
            out.append((_project(X, f, c, kk) - uv).ravel())
        return np.concatenate(out)

    sizes = [2 * len(uv) for _, _, uv in views]
    rows = [(slice(a, a + m), index[k]) for (k, _, _), a, m in zip(views, np.cumsum([0] + sizes[:-1]), sizes,
                                                                     strict=True)]

    def jacobian(x):
        # forward differences; a view's corners move only with the intrinsics, the mirror and its own
        # board's pose, so all boards' j-th pose parameter is stepped at once (17 evaluations, not 11 + 6 n)
        f0, h = residuals(x), 1.49e-8 * np.maximum(np.abs(x), 1.0)
        J = np.zeros((len(f0), len(x)))
        for j in range(11):
            xj = x.copy()
            xj[j] += h[j]
            J[:, j] = (residuals(xj) - f0) / h[j]
        for j in range(6):
            xj = x.copy()
            xj[11 + j::6] += h[11 + j::6]
            df = residuals(xj) - f0
            for r, i in rows:
                J[r, 11 + 6 * i + j] = df[r] / h[11 + 6 * i + j]
        return J

    fit = least_squares(residuals, x0, jac=jacobian, method="lm", x_scale="jac", xtol=1e-12, ftol=1e-12,
                        max_nfev=4000)
    f, c, kk, n, d, Rb, tb = unpack(fit.x)
    res = np.split(fit.fun.reshape(-1, 2), np.cumsum([len(uv) for _, _, uv in views])[:-1])
    which = np.array([view for _, view, _ in views])
    return f, c, kk, n, d, {k: (Rb[i], tb[i]) for k, i in index.items()}, res, which

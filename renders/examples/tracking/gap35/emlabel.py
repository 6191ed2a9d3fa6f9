"""Experiment: first-frame labels from both views at once by annealed EM (CPD-like) on the 3-D layout.

Markers X_i = s R (m_i - c + d_i) + c + t, d = scale * U sqrt(L) a, a ~ N(0, I) (physics prior).
Each view's dots are a mixture of the markers' projections (isotropic sigma px) and a uniform outlier.
"""
import numpy as np
from scipy.optimize import linear_sum_assignment


def _rot(w):
    th = np.linalg.norm(w)
    if th < 1e-12:
        return np.eye(3)
    k = w / th
    Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(th) * Kx + (1 - np.cos(th)) * Kx @ Kx


MODE = "rpm"
KAPPA = 3.0


def _softassign(num, slack, iters=30):
    P, k = num.shape
    M = np.full((P + 1, k + 1), slack)
    M[:P, :k] = num
    M[P, k] = 0.0
    for _ in range(iters):
        M[:P] /= np.maximum(M[:P].sum(1, keepdims=True), 1e-300)
        M[:, :k] /= np.maximum(M[:, :k].sum(0, keepdims=True), 1e-300)
    return M[:P, :k]


class Layout:
    def __init__(self, model, cov, scale_mm, modes_tol=1e-6):
        self.m = np.asarray(model, float)
        self.P = len(self.m)
        self.c = self.m[:-1].mean(0)          # lips' centre (the last row is the nose)
        lam, U = np.linalg.eigh(cov)
        keep = lam > modes_tol * lam.max()
        self.B = scale_mm * U[:, keep] * np.sqrt(lam[keep])     # (3P, k)
        self.k = int(keep.sum())

    def points(self, th):
        w, t, ls, a = th[:3], th[3:6], th[6], th[7:]
        d = (self.B @ a).reshape(self.P, 3)
        return np.exp(ls) * (self.m - self.c + d) @ _rot(w).T + self.c + t


def _proj_jac(cam, X, h=1e-3):
    u = cam.project(X)
    J = np.empty((len(X), 2, 3))
    for a in range(3):
        Xp = X.copy(); Xp[:, a] += h
        J[:, :, a] = (cam.project(Xp) - u) / h
    return u, J


def fit(dots, cameras, lay: Layout, th0=None, sigmas=None, w_out=0.2, inner=3, turn_sd=0.15, scale_sd=0.1,
        weights=None):
    """Annealed EM. dots: (virtual, real) (k_v, 2). Returns theta and the final per-view responsibilities."""
    n = 7 + lay.k
    th = np.zeros(n) if th0 is None else th0.copy()
    sigmas = np.geomspace(25, 1.5, 10) if sigmas is None else sigmas
    areas = [cam.width * cam.height for cam in cameras]
    for sig in sigmas:
        for _ in range(inner):
            X = lay.points(th)
            rows, jrows, rhs_w = [], [], []
            # E step and the M step's normal equations
            H = np.zeros((n, n)); g = np.zeros(n)
            for v, cam in enumerate(cameras):
                y = dots[v]
                if len(y) == 0:
                    continue
                u, Jp = _proj_jac(cam, X)
                D = ((y[None] - u[:, None]) ** 2).sum(2)            # (P, k)
                num = np.exp(-0.5 * D / sig ** 2)
                if weights is not None:
                    num = num * weights[v][None]
                if MODE == "rpm":
                    p = _softassign(num, np.exp(-0.5 * KAPPA ** 2))
                else:
                    c_out = 2 * np.pi * sig ** 2 * w_out / (1 - w_out) * lay.P / areas[v]
                    p = num / (num.sum(0, keepdims=True) + c_out)       # (P, k)
                nv = p.sum(1)
                ybar = (p @ y) / np.maximum(nv, 1e-300)[:, None]
                r = (ybar - u)                                       # (P, 2)
                JX = _dX_dth(th, lay)                                # (P, 3, n)
                Ju = np.einsum("pij,pjn->pin", Jp, JX)               # (P, 2, n)
                wgt = nv / sig ** 2
                H += np.einsum("p,pin,pim->nm", wgt, Ju, Ju)
                g += np.einsum("p,pin,pi->n", wgt, Ju, r)
            # priors: a ~ N(0, I); turn and log-scale weakly
            a = th[7:]
            H[7:, 7:] += np.eye(lay.k); g[7:] -= a
            H[:3, :3] += np.eye(3) / turn_sd ** 2; g[:3] -= th[:3] / turn_sd ** 2
            H[6, 6] += 1 / scale_sd ** 2; g[6] -= th[6] / scale_sd ** 2
            step = np.linalg.solve(H + 1e-9 * np.eye(n), g)
            th = th + step
    return th


def _dX_dth(th, lay, h=1e-6):
    """(P, 3, n) numerically (cheap: n ~ 58, P ~ 17)."""
    X0 = lay.points(th)
    J = np.empty((lay.P, 3, len(th)))
    for i in range(len(th)):
        t2 = th.copy(); t2[i] += h
        J[:, :, i] = (lay.points(t2) - X0) / h
    return J


def labels(dots, cameras, lay, th, gate_px=4.0, ratio=0.7):
    """Per view (P,) dot index or -1: one-to-one within gate, ambiguous ones left out."""
    X = lay.points(th)
    out = []
    for v, cam in enumerate(cameras):
        y = dots[v]
        lab = np.full(lay.P, -1)
        if len(y):
            u = cam.project(X)
            D = np.linalg.norm(y[None] - u[:, None], axis=2)
            big = 1e6
            C = np.where(D <= gate_px, D ** 2, big)
            r, c = linear_sum_assignment(np.hstack([C, np.full((lay.P, lay.P), gate_px ** 2)]))
            for i, j in zip(r, c):
                if j < len(y) and C[i, j] < big:
                    srt = np.sort(D[i])
                    if len(srt) > 1 and srt[0] > ratio * srt[1]:
                        continue
                    lab[i] = j
        out.append(lab)
    return out

SIDE = ['v']
import numpy as np
from lipgen.recon.dots import ink_gray, as_gray, refine_centroids
def gray_of(var, image):
    img = np.asarray(image)[..., :3].astype(np.float64) / 255.0
    if var == "main": return ink_gray(image)
    if var == "luma": return as_gray(image)
    if var == "green": return img[..., 1]
    if var == "mean": return img.mean(-1)
    if var == "red": return img[..., 0]
    raise ValueError(var)
def locate(var, image, start, sigma):
    return refine_centroids(gray_of(var, image), start, sigma, window=1.25)

def refine_multi(rgb, uv, sigma, window=1.25, iterations=15, chan_w=(1.0, 1.0, 1.0), sites=None):
    """Joint fit over channels: one centre and radius, per-channel amplitude and quadratic background."""
    rgb = np.asarray(rgb)[..., :3].astype(np.float64) / 255.0
    uv0 = np.asarray(uv, float).copy(); k = len(uv0)
    h, w = rgb.shape[:2]; half = int(np.ceil(3.0 * sigma)) + 1
    offs = np.arange(-half, half + 1, dtype=np.float64); base = np.round(uv0)
    cols = np.clip(base[:, 0, None] + offs, 0, w - 1).astype(np.int64)
    rows = np.clip(base[:, 1, None] + offs, 0, h - 1).astype(np.int64)
    img = np.stack([rgb[rows[:, :, None], cols[:, None, :], c].reshape(k, -1) for c in range(3)], 1)  # (k,3,pp)
    dy, dx = (a.ravel() for a in np.meshgrid(offs, offs, indexing="ij"))
    bg = np.stack([np.ones_like(dx), dx, dy, dx * dx, dx * dy, dy * dy], axis=1)  # (pp,6)
    cw = np.asarray(chan_w, float)[None, :, None]
    if sites is not None:
        cw = cw * np.stack([sites[rows[:, :, None], cols[:, None, :], c].reshape(k, -1) for c in range(3)], 1)
    def fit(p, wt):
        lam = np.full(k, 1e-3)
        def rj(p):
            u, v, s = p[:, 0:1], p[:, 1:2], p[:, 2:3]
            a = p[:, 3:6]; B = p[:, 6:].reshape(k, 3, 6)
            ex, ey = dx - u, dy - v; r2 = ex * ex + ey * ey; g = np.exp(-r2 / (2 * s * s))  # (k,pp)
            model = B @ bg.T - a[:, :, None] * g[:, None, :]
            J = np.zeros((k, 3, len(dx), 24))
            ag = a[:, :, None] * g[:, None, :]
            J[..., 0] = -ag * (ex / s ** 2)[:, None]; J[..., 1] = -ag * (ey / s ** 2)[:, None]
            J[..., 2] = -ag * (r2 / (s * s * s))[:, None]
            for c in range(3):
                J[:, c, :, 3 + c] = -g
                J[:, c, :, 6 + 6 * c:12 + 6 * c] = bg
            return (model - img).reshape(k, -1), J.reshape(k, -1, 24)
        W = (wt[:, None, :] * cw).reshape(k, -1)
        res, J = rj(p); cost = (W * res * res).sum(1); eye = np.eye(24)
        for _ in range(iterations):
            jt = (J * W[..., None]).transpose(0, 2, 1); jtj = jt @ J; jtr = (jt @ res[..., None])[..., 0]
            damp = jtj + lam[:, None, None] * (eye * np.diagonal(jtj, axis1=1, axis2=2)[:, None, :] + 1e-12 * eye)
            step = np.linalg.solve(damp, -jtr[..., None])[..., 0]
            tr = p + step; tr[:, 2] = np.clip(tr[:, 2], 0.3, 3.0 * sigma)
            rn, Jn = rj(tr); cn = (W * rn * rn).sum(1); b = cn < cost
            p[b], res[b], J[b], cost[b] = tr[b], rn[b], Jn[b], cn[b]
            lam = np.where(b, lam * 0.3, lam * 10.0)
        return p
    u = uv0[:, 0] - base[:, 0]; v = uv0[:, 1] - base[:, 1]
    g = np.exp(-((dx - u[:, None]) ** 2 + (dy - v[:, None]) ** 2) / (2 * sigma ** 2))
    p = np.zeros((k, 24)); p[:, 0], p[:, 1], p[:, 2] = u, v, sigma
    for c in range(3):
        D = np.concatenate([np.broadcast_to(bg, (k, *bg.shape)), -g[:, :, None]], axis=2)
        lin = (np.linalg.pinv(D) @ img[:, c, :, None])[..., 0]
        p[:, 3 + c] = lin[:, 6]; p[:, 6 + 6 * c:12 + 6 * c] = lin[:, :6]
    wt = np.exp(-((dx - u[:, None]) ** 2 + (dy - v[:, None]) ** 2) / (2 * (window * sigma) ** 2))
    p = fit(p, wt)
    wt = np.exp(-((dx - p[:, 0:1]) ** 2 + (dy - p[:, 1:2]) ** 2) / (2 * (window * sigma) ** 2))
    p = fit(p, wt)
    out = base + p[:, :2]
    bad = (np.abs(p[:, :2]).max(1) > half - 1) | ~np.isfinite(out).all(1)
    out[bad] = uv0[bad]
    return out

_old_locate = locate
def locate(var, image, start, sigma):
    if var == "multi":
        return refine_multi(image, start, sigma)
    if var.startswith("site"):
        H, Wd = image.shape[:2]
        m = np.zeros((H, 2 * Wd, 3))   # raw-frame RGGB sites, then the same split as the image
        m[0::2, 0::2, 0] = 1; m[0::2, 1::2, 1] = 1; m[1::2, 0::2, 1] = 1; m[1::2, 1::2, 2] = 1
        mv = m[:, :Wd][:, ::-1] if SIDE[0] == "v" else m[:, Wd:]
        cwt = {"siteR": (1, 0, 0), "siteRGB": (1, 1, 1), "siteG": (0, 1, 0)}[var]
        return refine_multi(image, start, sigma, chan_w=cwt, sites=mv)
    if var == "multiR2":
        return refine_multi(image, start, sigma, chan_w=(2.0, 1.0, 1.0))
    return _old_locate(var, image, start, sigma)

_old2 = locate
def locate(var, image, start, sigma):
    from scipy import ndimage
    if var.startswith("blur"):       # blurX[_win]: red (max) channel pre-blurred by X px
        parts = var[4:].split("_"); b = float(parts[0]); win = float(parts[1]) if len(parts) > 1 else 1.25
        g = ndimage.gaussian_filter(ink_gray(image), b) if b > 0 else ink_gray(image)
        return refine_centroids(g, start, float(np.hypot(sigma, b)), window=win)
    if var.startswith("win"):
        return refine_centroids(ink_gray(image), start, sigma, window=float(var[3:]))
    return _old2(var, image, start, sigma)

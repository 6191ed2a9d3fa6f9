"""The first frame seeded from one view, where the two views' 2-D matches agree on too few markers.

Each view's first frame is matched to the 2-D layout on its own
(:func:`lipgen.recon.firstframe.match_first_frame`), and a pair whose rays miss is dropped in both
views (:func:`lipgen.recon.grow.check_first_frame`): one of the two is wrong, and the ray gap does
not say which. When one view's registration failed as a whole, that drops nearly every pair, and
the other view's right matches with them. On ``hard`` 35 (the mouth open, the teeth showing in the
defocused mirror) the mirror matched 15 markers, 14 of them on tooth blobs and other markers' dots,
while the direct view matched all 17 right; 13 pairs were dropped, 2 were left, and with fewer than
3 markers seen in both views nothing grows (:func:`lipgen.recon.grow.grow_first_frame`), the
mirror's tracker never acquires (it places its layout on at least 3 markers) and no marker is
paired later (:func:`lipgen.recon.oneview.pair_one_view` needs 8): 6.5 % of the clip's sightings
were accepted.

One view's matches alone place the layout in 3-D, as a camera's pose is found from a known object
(here the markers at rest): each marker lies on its ray, so :func:`place_on_rays` fits a rigid
motion of the layout to the rays (orthogonal iteration, Lu, Hager and Mjolsness 2000, with the
translation solved in closed form for each rotation; the scale kept at the layout's; trimmed). A
registration on the wrong dots is not a turned lip layout: it is refused when the fit turns more
than ``max_turn`` (as :func:`lipgen.recon.grow.place_layout_3d` does). The depth along the rays is
the least known: the other view's dots that meet a marker's ray give its candidate points, the
offset from the placed layout that puts most markers near one of their candidates is voted
(:func:`seed_from_one_view`), then the rigid motion of the layout to those candidates is fitted
(twice). A marker then takes its nearest candidate when it is near and unambiguous; the markers so
paired that agree on the layout
(:func:`lipgen.recon.firstframe._consensus`) are the seeds the growth starts from. A view is taken when
it gives more than twice the other view's seeds (lures that are real things, the teeth, can pair
up too); the other view keeps only the seeds' dots. The seeding is not taken where it moves a pair
whose rays met (:func:`moves_pairs`): on ``hard`` 7 the mirror's seeds put ``bow_peak_right`` and
``bow_dip`` on their neighbours' dots in the direct view, one of them against a right pair.
"""

from __future__ import annotations

import numpy as np

from lipgen._validate import as_float_array
from lipgen.recon.firstframe import _consensus, checked_matches
from lipgen.recon.pointreg import layout_spacing
from lipgen.recon.stereo_init import _similarity_3d
from lipgen.rig.pinhole import PinholeCamera, triangulate

__all__ = ["place_on_rays", "seed_from_one_view", "moves_pairs"]


def place_on_rays(camera: PinholeCamera, uv, model, iterations: int = 60, k: float = 3.0,
                  floor: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """A rigid motion of the layout that puts each marker on its ray in one view.

    Parameters
    ----------
    camera : PinholeCamera
    uv : (n, 2) float
        The markers' dots in the view, pixels (n >= 4).
    model : (n, 3) float
        The same markers at rest in the frame of ``camera``, mm.
    iterations : int
        Orthogonal-iteration steps per round.
    k, floor : float
        A marker farther from its ray than ``k`` robust standard deviations of the distances (and
        ``floor`` mm) is left out of the next round (3 rounds at most, at least 4 markers kept).

    Returns
    -------
    placed : (n, 3) float
        The moved layout, mm.
    distance : (n,) float
        Each placed marker's distance from its ray, mm.
    used : (n,) bool
        The markers the last fit used.
    turn : float
        The motion's rotation, degrees.
    """
    X = as_float_array(model, "model", (None, 3))
    uv = as_float_array(uv, "uv", (len(X), 2))
    if len(X) < 4:
        raise ValueError(f"place_on_rays needs at least 4 markers, got {len(X)}")
    o, d = camera.rays(uv)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    used = np.ones(len(X), dtype=bool)
    R, t = np.eye(3), np.zeros(3)       # the layout is given at rest in the cameras' frame

    A = np.eye(3) - d[:, :, None] * d[:, None, :]     # (n, 3, 3): the part of a vector off each ray

    def off_ray(Y):
        return (Y - o) - d * np.sum((Y - o) * d, axis=1, keepdims=True)

    def best_t(R, use):
        """The translation that puts the turned layout nearest its rays (closed form, LHM eq. 20)."""
        Au = A[use]
        return np.linalg.solve(Au.sum(0), np.einsum("nij,nj->i", Au, o[use] - X[use] @ R.T))

    for _ in range(3):
        t = best_t(R, used)
        for _ in range(iterations):
            Y = X @ R.T + t
            R = _similarity_3d(X[used], (Y - off_ray(Y))[used], max_scale_change=0.0)[:3, :3]
            t = best_t(R, used)
        dist = np.linalg.norm(off_ray(X @ R.T + t), axis=1)
        new = dist <= max(k * 1.4826 * float(np.median(dist[used])), floor)
        if new.sum() < 4 or np.array_equal(new, used):
            break
        used = new
    turn = float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0))))
    return X @ R.T + t, dist, used, turn


def _pairs_of(cameras, uv_a: np.ndarray, a: int, dots_b: np.ndarray, max_gap: float
              ) -> tuple[np.ndarray, np.ndarray]:
    """3-D points of one view-``a`` dot paired with each dot of the other view whose ray meets it.

    Returns (points (c, 3), indices (c,) into ``dots_b``)."""
    if len(dots_b) == 0:
        return np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
    ua = np.repeat(uv_a[None], len(dots_b), axis=0)
    uv = (ua, dots_b) if a == 0 else (dots_b, ua)        # (virtual, real)
    X, gap = triangulate(cameras[1], uv[1], cameras[0], uv[0])
    ok = np.flatnonzero(gap <= max_gap)
    return X[ok], ok


def _seeds_from(a: int, out, dots, cameras, model, max_gap, near, ratio, max_turn, reach, tol
                ) -> tuple[np.ndarray, np.ndarray]:
    """View ``a``'s matches paired with the other view's dots near the layout placed on ``a``'s rays.

    Returns (seeds (P,) bool, the other view's dot per marker (P,) int, -1 where none)."""
    P = len(model)
    b = 1 - a
    got = np.full(P, -1)
    m = np.all(np.isfinite(out[a]), axis=1) & np.all(np.isfinite(model), axis=1)
    if m.sum() < 4 or len(dots[b]) == 0:
        return np.zeros(P, dtype=bool), got
    placed = np.full((P, 3), np.nan)
    placed[m], _, _, turn = place_on_rays(cameras[a], out[a][m], model[m])
    if turn > max_turn:          # a registration on the wrong dots, not the head's turn
        return np.zeros(P, dtype=bool), got
    cand = {i: _pairs_of(cameras, out[a][i], a, dots[b], max_gap) for i in np.flatnonzero(m)}
    offsets = [X - placed[i] for i, (X, _) in cand.items() if len(X)]
    if not offsets:
        return np.zeros(P, dtype=bool), got
    offsets = np.concatenate(offsets)
    offsets = offsets[np.linalg.norm(offsets, axis=1) <= reach]
    best, best_key = np.zeros(3), (-1, 0.0)
    for h in offsets:             # the depth the rays leave open: the offset most markers agree on
        dmin = np.array([np.linalg.norm(X - (placed[i] + h), axis=1).min() for i, (X, _) in cand.items()
                         if len(X)])
        hit = dmin <= tol
        key = (int(hit.sum()), -float(dmin[hit].sum()))
        if key > best_key:
            best, best_key = h, key
    pred = placed + best
    for _ in range(2):           # then the rigid motion that fits the layout to the nearest candidates
        near_X = np.full((P, 3), np.nan)
        for i, (X, _) in cand.items():
            if len(X):
                j = int(np.linalg.norm(X - pred[i], axis=1).argmin())
                if np.linalg.norm(X[j] - pred[i]) <= tol:
                    near_X[i] = X[j]
        hit = np.all(np.isfinite(near_X), axis=1)
        if hit.sum() < 4:
            break
        T = _similarity_3d(model[hit], near_X[hit], max_scale_change=0.0)
        pred = np.where(m[:, None], model @ T[:3, :3].T + T[:3, 3], np.nan)
    X3 = np.full((P, 3), np.nan)
    for i, (X, idx) in cand.items():
        if len(X) == 0:
            continue
        dist = np.linalg.norm(X - pred[i], axis=1)
        o = np.argsort(dist)
        if dist[o[0]] > near or (len(o) > 1 and dist[o[0]] >= ratio * dist[o[1]]):
            continue
        others = np.flatnonzero(m & (np.arange(P) != i))
        if len(others) and np.linalg.norm(pred[others] - X[o[0]], axis=1).min() <= dist[o[0]]:
            continue             # nearer another marker's place than its own
        got[i], X3[i] = idx[o[0]], X[o[0]]
    seeds = got >= 0
    dup = np.flatnonzero(np.bincount(got[seeds], minlength=len(dots[b])) > 1)
    seeds &= ~np.isin(got, dup)  # one dot for two markers: neither
    if seeds.sum() >= 3:
        seeds = _consensus(model, X3, seeds, 0.5 * layout_spacing(model[np.all(np.isfinite(model), axis=1)]))
    got[~seeds] = -1
    return seeds, got


def seed_from_one_view(inits, dots, cameras: tuple[PinholeCamera, PinholeCamera], model_points,
                       max_gap: float, min_seeds: int = 3, near: float = 0.8, ratio: float = 0.6,
                       max_turn: float = 15.0, reach: float = 40.0, tol: float = 0.4
                       ) -> tuple[list[np.ndarray], int | None]:
    """Seed the first frame from the view whose matches the other view's dots confirm best.

    Parameters
    ----------
    inits : (virtual, real) (P, 2) float
        Each view's first-frame 2-D matches (dot centres), NaN where unmatched.
    dots : (virtual, real) (m, 2), (n, 2) float
        All dots found in each view's first frame.
    cameras : (virtual, real) PinholeCamera
    model_points : (P, 3) float
        The markers at rest in the frame of ``cameras``, mm (NaN rows: markers without a layout).
    max_gap : float
        Largest distance between the two rays of a pair, mm.
    min_seeds : int
        Fewest seeds for a view to be taken.
    near : float
        Largest distance from a marker's placed point to its pair's point, in layout spacings.
    ratio : float
        A pair must be nearer than ``ratio`` times the marker's next candidate.
    max_turn : float
        Largest rotation (degrees) of the layout placed on one view's rays.
    reach : float
        Largest voted offset of the placed layout, mm.
    tol : float
        A marker votes for an offset that puts one of its candidates within ``tol`` spacings.

    Returns
    -------
    inits : (virtual, real) (P, 2) float
        Copies: the taken view keeps all its matches, the other only the seeds' dots (the seeds
        are matched in both views). Unchanged when no view gives ``min_seeds`` seeds and more
        than twice the other view's.
    view : int or None
        The view taken (0 virtual, 1 real), None when none.
    """
    model, out = checked_matches(model_points, inits)
    dv = [as_float_array(d, "dots", (None, 2)) for d in dots]
    if min_seeds < 3:
        raise ValueError(f"min_seeds must be at least 3, got {min_seeds!r}")
    has = np.all(np.isfinite(model), axis=1)
    if has.sum() < 4:
        return out, None
    width = layout_spacing(model[has])
    found = [_seeds_from(a, out, dv, cameras, model, max_gap, near * width, ratio, max_turn, reach,
                         tol * width) for a in range(2)]
    n = [int(s.sum()) for s, _ in found]
    a = int(np.argmax(n))
    if n[a] < min_seeds or n[a] <= 2 * n[1 - a]:   # nothing to go on, or no view clearly preferred
        return out, None
    seeds, got = found[a]
    other = np.full_like(out[1 - a], np.nan)
    other[seeds] = dv[1 - a][got[seeds]]
    out[1 - a] = other
    return out, a


def moves_pairs(seeded, inits, pairs, tol: float = 0.5) -> bool:
    """Whether a seeding moves a pair the two views agree on.

    Parameters
    ----------
    seeded, inits : (virtual, real) (P, 2) float
        The seeding's matches and the matches left after the ray-gap check.
    pairs : (P,) bool
        The markers matched in both views of ``inits`` (their rays met).
    tol : float
        Pixels within which two dots are one.

    Returns
    -------
    bool
        True when, in some view, the seeding matches such a marker to another dot, or gives its
        dot to another marker.
    """
    for v in range(2):
        s, u = np.asarray(seeded[v], dtype=float), np.asarray(inits[v], dtype=float)
        for i in np.flatnonzero(pairs):
            d = np.linalg.norm(s - u[i], axis=1)
            d[~np.isfinite(d)] = np.inf
            if np.all(np.isfinite(s[i])) and d[i] > tol:
                return True
            d[i] = np.inf
            if (d <= tol).any():
                return True
    return False

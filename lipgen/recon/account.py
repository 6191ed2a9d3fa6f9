"""An account of every marker sighting of a reconstruction: nothing is lost in silence.

Each (frame, mark) is one of:

* **accepted**: seen in both views, the two rays pass within ``max_ray_gap`` (they agree), and
  the normalisation did not find it mis-measured: it is a goal of the frame's field;
* **rejected**: seen, but the views disagree (the tracker took the sighting back, or the rays pass
  too far apart), or the normalisation left it out as an outlier;
* **unpaired**: seen in one view only (the other lost it), so nothing can check it;
* **lost**: found in neither view.

:func:`sighting_account` counts them per mark (and per view: lost, rejected), and names each mark
never tracked in a view with the reason, e.g. ``"upper_mid: within 2.1 px of bow_dip at this
resolution"``. :func:`account_lines` turns it into the summary ``lipgen reconstruct`` prints.
"""

from __future__ import annotations

import numpy as np

from lipgen.recon.track import LOST, twin_partners
from lipgen.rig.camera import VIEWS

__all__ = ["sighting_account", "account_lines", "missing_marks"]


def _reason(v: int, j: int, names, tracks, expected, sizes, twins: float) -> str:
    """Why mark ``j`` was never tracked in view ``v``."""
    other = VIEWS[1 - v]
    e = expected[v, j]
    w, h = sizes[v]
    if not np.all(np.isfinite(e)) or not (0 <= e[0] <= w - 1 and 0 <= e[1] <= h - 1):
        return "its expected place is outside this view"
    partner, dist = twin_partners(np.where(np.isfinite(expected[v]), expected[v], 1e9), twins)
    if partner[j] >= 0:
        return (f"within {dist[j]:.1f} px of {names[partner[j]]} at this resolution (dots closer than "
                f"{twins:.1f} px merge and are not told apart)")
    rej = tracks[v].rejected
    n_rej = 0 if rej is None else int(rej[:, j].sum())
    if n_rej:
        return f"all {n_rej} sighting(s) contradicted by the {other} view (rays too far apart)"
    return "no dot found near where the layout of the other markers puts it"


def _missing_reason(j: int, seen, disagree, unpaired, view_reason) -> str:
    """Why mark ``j`` has no accepted sighting: per view how often it was lost, and what became of the rest.

    ``view_reason(v)`` explains a view that lost the mark in most frames (see :func:`_reason`).
    """
    F = seen.shape[1]
    parts = []
    for v, view in enumerate(VIEWS):
        n_lost = F - int(seen[v, :, j].sum())
        if n_lost == F:
            parts.append(f"never tracked in the {view} view ({view_reason(v)})")
        elif n_lost > F // 2:
            parts.append(f"lost in the {view} view in {n_lost} of {F} frames ({view_reason(v)})")
        elif n_lost:
            parts.append(f"lost in the {view} view in {n_lost} of {F} frames")
    n_dis, n_one = int(disagree[:, j].sum()), int(unpaired[:, j].sum())
    if n_dis:
        parts.append(f"the views disagree in {n_dis} frame(s)")
    if n_one:
        parts.append(f"seen in one view only in {n_one} frame(s)")
    return "; ".join(parts) or "lost in every frame"


def sighting_account(tracks, visible, ray_gap, max_ray_gap: float, outliers, names, expected, sizes,
                     twins: float) -> dict:
    """Count each mark's sightings and explain the marks never tracked in a view.

    Parameters
    ----------
    tracks : (virtual, real) Tracks
        Of the P + 1 marks (markers then nose).
    visible : (F, P + 1) bool
        Accepted by the triangulation (both views, rays within ``max_ray_gap``).
    ray_gap : (F, P + 1) float
        Distance between the rays, mm (NaN where a view lost the mark).
    max_ray_gap : float
    outliers : (F, P) bool
        Marker sightings the normalisation left out.
    names : sequence of str
        The P + 1 mark names.
    expected : (2, P + 1, 2) float
        Expected layout per view, pixels.
    sizes : ((w, h), (w, h))
        Split-view image sizes.
    twins : float
        The tracker's twin distance, pixels.

    Returns
    -------
    dict
        ``frames``; ``per_mark``: name -> {accepted, rejected, unpaired, lost, lost_virtual,
        lost_real, rejected_virtual, rejected_real}; ``never_tracked``: [{mark, view, reason}];
        ``missing``: names of marks with no accepted sighting; ``never_accepted``: [{mark, reason}] for
        each of them; ``accepted_share``.
    """
    F = len(visible)
    seen = np.stack([t.status != LOST for t in tracks])                         # (2, F, P+1)
    taken_back = np.stack([np.zeros(seen.shape[1:], bool) if t.rejected is None else t.rejected
                           for t in tracks])
    out_all = np.zeros_like(visible)
    out_all[:, :outliers.shape[1]] = outliers
    accepted = visible & ~out_all
    disagree = (seen[0] & seen[1] & ~visible) | (visible & out_all) | (taken_back.any(0) & ~accepted)
    unpaired = (seen[0] ^ seen[1]) & ~disagree
    lost = ~accepted & ~disagree & ~unpaired
    per_mark = {}
    for j, name in enumerate(names):
        per_mark[str(name)] = {
            "accepted": int(accepted[:, j].sum()), "rejected": int(disagree[:, j].sum()),
            "unpaired": int(unpaired[:, j].sum()), "lost": int(lost[:, j].sum()),
            **{f"lost_{view}": int((~seen[v, :, j] & ~taken_back[v, :, j]).sum())
               for v, view in enumerate(VIEWS)},
            **{f"rejected_{view}": int(taken_back[v, :, j].sum()) for v, view in enumerate(VIEWS)}}
    never = [{"mark": str(names[j]), "view": VIEWS[v], "reason": _reason(v, j, names, tracks, expected, sizes,
                                                                          twins)}
             for v in range(2) for j in range(len(names)) if not seen[v, :, j].any()]
    missing = [j for j in range(len(names)) if not accepted[:, j].any()]
    def view_reason(j):
        return lambda v: _reason(v, j, names, tracks, expected, sizes, twins)

    why_missing = [{"mark": str(names[j]),
                    "reason": _missing_reason(j, seen, disagree, unpaired, view_reason(j))} for j in missing]
    return {"frames": F, "max_ray_gap_mm": float(max_ray_gap), "per_mark": per_mark, "never_tracked": never,
            "missing": [str(names[j]) for j in missing], "never_accepted": why_missing,
            "accepted_share": float(accepted.mean()),
            "categories": "accepted: both views agree; rejected: the views disagree (or a pose outlier); "
                          "unpaired: one view only; lost: neither view"}


def missing_marks(account: dict) -> list[str]:
    """Names of the marks with no accepted sighting in any frame."""
    return list(account.get("missing", []))


def account_lines(account: dict, reasons: bool = True) -> list[str]:
    """The human summary: one line per mark, then (``reasons``) each never-tracked mark with why."""
    F = account["frames"]
    names = list(account["per_mark"])
    wide = max(len(n) for n in names)
    lines = [f"sightings over {F} frames: accepted (both views agree) / rejected (views disagree or pose "
             "outlier) / unpaired (one view) / lost (lost in virtual, real)"]
    for name in names:
        c = account["per_mark"][name]
        flag = "" if c["accepted"] == F else ("  <- NEVER ACCEPTED" if c["accepted"] == 0 else "")
        lines.append(f"  {name:<{wide}} {c['accepted']:4d} / {c['rejected']:3d} / {c['unpaired']:3d} / "
                     f"{c['lost']:3d} ({c['lost_virtual']}, {c['lost_real']}){flag}")
    for n in account["never_tracked"] if reasons else ():
        lines.append(f"never tracked in the {n['view']} view: {n['mark']}: {n['reason']}")
    for n in account.get("never_accepted", []) if reasons else ():
        lines.append(f"never accepted: {n['mark']}: {n['reason']}")
    return lines

"""Predictor experiment: move free nodes with the jaw's incremental rigid motion, weighted by how much each
node follows the jaw in the linear rest response (computed once)."""
import sys, time, json
import numpy as np
import scipy.sparse.linalg as sla
from lipgen.dataset.settings import GenerateSettings
import lipgen.subject.truth as TR
from lipgen.dataset.simulation import simulate_motion
import lipgen.subject.layer as L
seed, frames, mode, out = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3], sys.argv[4]
TOL = float(__import__("os").environ.get("TOL", "1e-4"))
_os = L.Layer.solve
L.Layer.solve = lambda self, *a, **k: _os(self, *a, **{**k, "tol": TOL, "maxiter": 400})
ev = {"e": 0, "f": 0}
oe, of = L.Layer.energy_grad, L.Layer._factor
def en(*a, **k):
    ev["e"] += 1; return oe(*a, **k)
def fa(self, x=None, active=None):
    ev["f"] += x is not None; return of(self, x, active)
L.Layer.energy_grad, L.Layer._factor = en, fa
orig_solve = L.Layer.solve
st = {}
def follow_weight(layer, bw):
    n2 = len(layer.rest); free = ~layer.fixed
    dof = np.arange(3 * n2).reshape(n2, 3)[:, 1]   # y dofs only: a scalar field
    K = layer.K0.tocsr()[dof][:, dof]
    rhs_fixed = bw.astype(float)
    Kff = K[free][:, free] + __import__("scipy.sparse", fromlist=["diags"]).diags(layer.gum[free].astype(float))
    b = -K[free][:, layer.fixed] @ rhs_fixed[layer.fixed] + layer.gum[free] * 1.0
    w = rhs_fixed.copy(); w[free] = sla.spsolve(Kff.tocsc(), b)
    return w
def layer_displacements(subject, A, progress=False):
    from lipgen.subject.sources import _jaw_rigid
    from lipgen.subject.activation import action_index
    layer = subject.layer; n = subject.mesh.n_nodes; X2 = layer.rest
    side = A[:, action_index("jaw_shift_left")] - A[:, action_index("jaw_shift_right")]
    angles = A[:, action_index("jaw_open")] * subject.jaw_max_angle
    rigid = _jaw_rigid(X2, angles, subject.jaw_max_angle, subject.jaw_shift_mm * side)
    bw = np.concatenate([subject.border_weight, subject.border_weight])
    w = follow_weight(layer, bw) if mode != "none" else None
    outv = np.zeros((len(A), n, 3)); x = X2.copy()
    for f in range(len(A)):
        force = np.zeros_like(X2); force[:n] = np.einsum("a,ani->ni", A[f], subject.layer_forces)
        prescribed = X2 + bw[:, None] * rigid[f]
        if w is not None and f > 0:
            x = x + w[:, None] * (rigid[f] - rigid[f - 1])
        x = layer.solve(force, prescribed, x0=x, gum_target=X2 + rigid[f], active=TR.layer_active(subject, A[f]))
        outv[f] = x[:n] - X2[:n]
    return outv
TR.layer_displacements = layer_displacements
t0 = time.process_time(); m = simulate_motion(GenerateSettings.from_preset("hard", seed=seed, frames=frames))
np.save(out, m.vertices)
print(json.dumps(dict(seed=seed, mode=mode, cpu=round(time.process_time() - t0, 2), **ev)))

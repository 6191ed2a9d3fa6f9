import numpy as np
from lipgen.dataset.settings import GenerateSettings
import lipgen.subject.truth as TR
import lipgen.dataset.simulation as SIM
from lipgen.subject.sources import _jaw_rigid
from lipgen.subject.activation import action_index
cap = {}
orig = TR.layer_displacements
def spy(subject, A, progress=False):
    cap["subject"], cap["A"] = subject, A
    return orig(subject, A, progress)

TR.layer_displacements = spy
SIM.simulate_motion(GenerateSettings.from_preset("hard", seed=5, frames=30))
subject, A = cap["subject"], cap["A"]
layer = subject.layer; n = subject.mesh.n_nodes; X2 = layer.rest
side = A[:, action_index("jaw_shift_left")] - A[:, action_index("jaw_shift_right")]
angles = A[:, action_index("jaw_open")] * subject.jaw_max_angle
rigid = _jaw_rigid(X2, angles, subject.jaw_max_angle, subject.jaw_shift_mm * side)
bw = np.concatenate([subject.border_weight, subject.border_weight])
def params(f):
    force = np.zeros_like(X2); force[:n] = np.einsum("a,ani->ni", A[f], subject.layer_forces)
    return force, X2 + bw[:, None] * rigid[f], X2 + rigid[f], TR.layer_active(subject, A[f])
x = X2.copy()
for f in range(14):
    fo, pr, gt, ac = params(f)
    if f > 0:
        fo0, pr0, gt0, ac0 = params(f - 1)
        def E(fo_, pr_, gt_, ac_):
            y = x.copy(); y[layer.fixed] = pr_[layer.fixed]
            return layer.energy_grad(y, fo_, gt_, ac_)[0]
        base = E(fo0, pr0, gt0, ac0)
        print(f, "prev %.0f | force %.0f | prescribed %.0f | gum %.0f | active %.0f | all %.0f" % (
            base, E(fo, pr0, gt0, ac0), E(fo0, pr, gt0, ac0), E(fo0, pr0, gt, ac0), E(fo0, pr0, gt0, ac), E(fo, pr, gt, ac)))
    x = layer.solve(fo, pr, x0=x, gum_target=gt, active=ac)

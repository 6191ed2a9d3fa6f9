import time, numpy as np
from lipgen.dataset.settings import GenerateSettings
from lipgen.dataset.simulation import simulate_motion
import lipgen.subject.layer as L
import lipgen.subject.layer_stiffness as LS
cap = {}
orig = L.Layer.solve
def so(self, *a, **k):
    r = orig(self, *a, **k); cap.update(layer=self, x=r, k=k); return r
L.Layer.solve = so
simulate_motion(GenerateSettings.from_preset("hard", seed=5, frames=4))
lay, x, k = cap["layer"], cap["x"], cap["k"]
Dm = lay._dm_inv(k.get("active"))
def old(x, tets, Dm_inv, volume, mu, lam, kappa, psd):
    C = LS.stress_derivative(LS.deformation_gradients(x, tets, Dm_inv), mu, lam, kappa, psd=psd)
    gN = np.concatenate([-Dm_inv.sum(axis=1, keepdims=True), Dm_inv], axis=1)
    G = np.zeros((len(tets), 9, 12))
    for i in range(3):
        for a in range(4):
            G[:, 3 * i:3 * i + 3, 3 * a + i] = gN[:, a, :]
    K = volume[:, None, None] * np.swapaxes(G, 1, 2) @ C @ G
    return 0.5 * (K + np.swapaxes(K, 1, 2))
args = (x, lay.tets, Dm, lay.volume, lay.mu, lay.lam, lay.kappa, True)
best = {"old": [], "new": []}
for r in range(15):
    for name, f in (("old", old), ("new", LS.tet_hessians)) if r % 2 else (("new", LS.tet_hessians), ("old", old)):
        t0 = time.perf_counter(); f(*args); best[name].append(time.perf_counter() - t0)
print({k: "min %.2f ms median %.2f ms" % (1e3 * min(v), 1e3 * np.median(v)) for k, v in best.items()})
print("agree", np.abs(old(*args) - LS.tet_hessians(*args)).max() / np.abs(old(*args)).max())
def t(name, f, n=30):
    ts = []
    for _ in range(n):
        t0 = time.perf_counter(); r = f(); ts.append(time.perf_counter() - t0)
    print(f"{name}: min {1e3 * min(ts):.3f} ms"); return r
F = t("F", lambda: LS.deformation_gradients(x, lay.tets, Dm))
_, _, S, cof, J = t("strain", lambda: LS.strain_state(F, lay.mu, lay.lam))
t("eigvals", lambda: LS.symmetric_eigenvalues(S))
t("positive_part", lambda: LS.positive_part(S))
t("eigh", lambda: np.linalg.eigh(S))
lam = LS.symmetric_eigenvalues(S); print("n_pos counts", np.bincount((lam > 0).sum(1), minlength=4))
S2 = LS.positive_part(S)
gN = t("gN", lambda: np.concatenate([-Dm.sum(axis=1, keepdims=True), Dm], axis=1))
gNt = np.swapaxes(gN, 1, 2)
A = t("A", lambda: gN @ S2 @ gNt)
B = t("B", lambda: lay.mu[:, None, None] * (gN @ gNt))
M = t("M", lambda: F @ np.swapaxes(F, 1, 2))
v = t("v", lambda: gN @ np.swapaxes(F, 1, 2))
wc = t("w", lambda: gN @ np.swapaxes(cof, 1, 2))
K = t("BM", lambda: B[:, :, None, :, None] * M[:, None, :, None, :])
def fa():
    K[:, :, [0, 1, 2], :, [0, 1, 2]] += A[None]
t("fancyA", fa)
def t3():
    global K
    K += lay.mu[:, None, None, None, None] * np.swapaxes(v, 1, 2)[:, None, :, :, None] * v[:, :, None, None, :]
t("term3", t3)
T = len(F)
K2 = K.reshape(T, 12, 12)
vf, wf = v.reshape(T, 12), wc.reshape(T, 12)
def r1():
    K2[:] += lay.lam[:, None, None] * vf[:, :, None] * vf[:, None, :]
t("rank1", r1)
t("vol", lambda: K2 * lay.volume[:, None, None])
t("sym", lambda: 0.5 * (K2 + np.swapaxes(K2, 1, 2)))

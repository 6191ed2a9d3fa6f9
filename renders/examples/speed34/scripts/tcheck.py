import numpy as np, time
from lipgen.subject.layer_stiffness import stress_derivative, tet_hessians
rng = np.random.default_rng(0)
T = 4176
F = np.eye(3) + 0.3 * rng.normal(size=(T, 3, 3))
Dm_inv = rng.normal(size=(T, 3, 3))
gN = np.concatenate([-Dm_inv.sum(axis=1, keepdims=True), Dm_inv], axis=1)  # (T,4,3)
vol, mu, lam, kappa = rng.uniform(0.5, 1, T), rng.uniform(0.5, 2, T), rng.uniform(0, 3, T), rng.uniform(1, 40, T)
def ref(psd):
    C = stress_derivative(F, mu, lam, kappa, psd=psd)
    G = np.zeros((T, 9, 12))
    for i in range(3):
        for a in range(4):
            G[:, 3 * i:3 * i + 3, 3 * a + i] = gN[:, a, :]
    return vol[:, None, None] * np.swapaxes(G, 1, 2) @ C @ G
Ft, gt = np.ascontiguousarray(F.transpose(1, 2, 0)), np.ascontiguousarray(gN.transpose(1, 2, 0))
for psd in (True, False):
    R = ref(psd); K = tet_hessians(Ft, gt, vol, mu, lam, kappa, psd).transpose(2, 0, 1)
    print(psd, np.abs(R - K).max() / np.abs(R).max(), np.abs(K - K.transpose(0, 2, 1)).max() / np.abs(K).max())
for _ in range(3):
    t = time.perf_counter(); ref(True); t1 = time.perf_counter(); tet_hessians(Ft, gt, vol, mu, lam, kappa, True); t2 = time.perf_counter()
    print("ms ref", round((t1 - t) * 1e3, 2), "new", round((t2 - t1) * 1e3, 2))

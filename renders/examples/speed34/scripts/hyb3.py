import sys, json, os
import numpy as np
from scipy.sparse.linalg import splu
from lipgen.dataset.settings import GenerateSettings
from lipgen.dataset.simulation import simulate_motion
import lipgen.subject.layer as L
seed, frames = int(sys.argv[1]), int(sys.argv[2])
REFAC = int(os.environ.get("REFAC", "1000")); HYB = int(os.environ.get("HYB", "1"))
ev = {"evals": 0, "factorisations": 0, "exact_ok": 0, "exact_fail": 0, "steps": 0}
oe = L.Layer._energy_grad
def en(*a, **k):
    ev["evals"] += 1; return oe(*a, **k)

import cvxopt
from cvxopt import cholmod
def make_chol(self, K):
    if "chol" not in self.cache:
        K = K.tocsc(); K.sort_indices(); n = K.shape[0]
        rows = K.indices; cols = np.repeat(np.arange(n), np.diff(K.indptr)); low = rows >= cols
        M = cvxopt.spmatrix(cvxopt.matrix(K.data[low]), cvxopt.matrix(rows[low].astype(np.int64)), cvxopt.matrix(cols[low].astype(np.int64)), (n, n))
        cholmod.options["supernodal"] = 2
        self.cache["chol"] = (M, cholmod.symbolic(M, uplo="L"), low)
    M, Fs, low = self.cache["chol"]
    M.V = cvxopt.matrix(K.data[low])
    F = cholmod.symbolic(M, uplo="L") if False else Fs
    cholmod.numeric(M, F)
    return F
def fa(self, x=None, active=None):
    if x is None:
        return L.Layer._factor_orig(self, x, active)
    ev["factorisations"] += 1
    for psd in ((False, True) if HYB else (True,)):
        K = self.tangent(x, psd=psd, active=active, free_only=True) + 1e-9 * self.cache["diag"]
        try:
            F = make_chol(self, K)
        except ArithmeticError:
            ev["exact_fail"] += 1; continue
        ev["exact_ok"] += not psd
        # numeric overwrites F: copy semantics -> keep a fresh symbolic per factor
        def solve(b, F=F):
            X = cvxopt.matrix(b); cholmod.solve(F, X); return np.array(X).ravel()
        return solve

def solve(self, force, prescribed, x0=None, gum_target=None, tol=1e-4, maxiter=100, callback=None, active=None):
    free = ~self.fixed
    x = (self.rest if x0 is None else np.asarray(x0, float)).copy()
    x[self.fixed] = prescribed[self.fixed]
    kinematics = self._kinematics(active)
    solve = self.cache.get("last", self._factor())
    e, g = self._energy_grad(x, force, gum_target, kinematics)
    memory = []; since = 0
    for it in range(maxiter):
        ev["steps"] += 1
        step = -L._lbfgs_direction(g[free].ravel(), memory, solve).reshape(-1, 3)
        slope = float(np.sum(g[free] * step))
        if not slope < 0:
            memory.clear()
            step = -solve(g[free].ravel()).reshape(-1, 3)
            slope = float(np.sum(g[free] * step))
            if not slope < 0:
                solve = L.Layer._factor_orig(self, x, active); self.cache["last"] = solve
                step = -solve(g[free].ravel()).reshape(-1, 3); slope = float(np.sum(g[free] * step))
        alpha, trial = 1.0, x.copy()
        while True:
            trial[free] = x[free] + alpha * step
            e_new, g_new = self._energy_grad(trial, force, gum_target, kinematics)
            if e_new <= e + 1e-4 * alpha * slope or alpha < 1e-6:
                break
            curvature = e_new - e - slope * alpha
            guess = -slope * alpha * alpha / (2.0 * curvature) if curvature > 0 else 0.5 * alpha
            alpha = min(max(guess, 0.1 * alpha), 0.5 * alpha)
        if e_new > e:
            break
        s_k = (alpha * step).ravel(); y_k = (g_new[free] - g[free]).ravel()
        x, e, g = trial, e_new, g_new
        since += 1
        if alpha * np.abs(step).max() < tol:
            break
        if alpha < 1.0 or since >= REFAC:
            solve = self._factor(x, active); self.cache["last"] = solve; memory.clear(); since = 0
        elif (sy := float(s_k @ y_k)) > 1e-12 * float(s_k @ s_k):
            memory.append((s_k, y_k, 1.0 / sy)); del memory[:-L.LBFGS_MEMORY]
    else:
        print("cap", file=sys.stderr)
    self.iterations.append(it + 1)
    return x
L.Layer._factor_orig = L.Layer._factor
L.Layer._energy_grad = en; L.Layer._factor = fa; L.Layer.solve = solve
s = GenerateSettings.from_preset("hard", seed=seed, frames=frames) if seed >= 0 else GenerateSettings.from_preset("hard", frames=frames)
import time; t = time.process_time()
m = simulate_motion(s)
cpu = time.process_time() - t
tag = os.environ.get("TAG", "h")
np.save(f"/work/b34/V_{seed}_{tag}.npy", m.vertices)
print(json.dumps(dict(tag=tag, REFAC=REFAC, HYB=HYB, seed=seed, frames=frames, cpu=round(cpu, 2), **ev)))

import sys, time
sys.path.insert(0, "/work/b34/pkgs")
import numpy as np, scipy.sparse as sp
from lipgen.subject.layer_stiffness import fill_reducing_order, spd_solver
Ks = [sp.load_npz(f"/work/b34/K{i}.npz") for i in range(0, 12, 2)]  # psd ones
n = Ks[0].shape[0]
b = np.random.default_rng(0).standard_normal(n)
def tm(f, reps=3):
    best = 1e9
    for _ in range(reps):
        t = time.perf_counter(); f(); best = min(best, time.perf_counter() - t)
    return best * 1e3
order = fill_reducing_order(Ks[0])
print("superlu factor ms", [round(tm(lambda: spd_solver(K, order)), 1) for K in Ks[:3]])
s = spd_solver(Ks[0], order); print("superlu solve ms", round(tm(lambda: s(b), 10), 2))
from scipy.sparse.linalg import splu
lu = splu(Ks[0].tocsr()[order][:, order].tocsc(), permc_spec="NATURAL", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
print("superlu nnz L+U", lu.L.nnz + lu.U.nnz)
# cvxopt cholmod
from cvxopt import spmatrix, matrix, cholmod
cholmod.options['supernodal'] = 2
def tocvx(K):
    C = sp.tril(K).tocoo()
    return spmatrix(C.data, C.row.astype(int), C.col.astype(int), (n, n))
A = tocvx(Ks[0]); Fs = cholmod.symbolic(A, uplo='L')
print("cholmod symbolic ms", round(tm(lambda: cholmod.symbolic(tocvx(Ks[0]), uplo='L'), 3), 1))
print("cvx convert ms", round(tm(lambda: tocvx(Ks[1])), 1))
def num(K):
    A = tocvx(K); cholmod.numeric(A, Fs)
print("cholmod numeric ms", [round(tm(lambda: num(K)), 1) for K in Ks[:3]])
num(Ks[0])
B = matrix(b)
def cs():
    X = matrix(b); cholmod.solve(Fs, X)
    return np.array(X).ravel()
print("cholmod solve ms", round(tm(cs, 10), 2))
x1 = cs(); x0 = s(b); print("agree", np.abs(x1 - x0).max() / np.abs(x0).max())
import qdldl
Q = qdldl.Solver(sp.triu(Ks[0]).tocsc())
print("qdldl first ms", round(tm(lambda: qdldl.Solver(sp.triu(Ks[0]).tocsc())), 1))
print("qdldl update ms", [round(tm(lambda: Q.update(sp.triu(K).tocsc())), 1) for K in Ks[:3]])
Q.update(sp.triu(Ks[0]).tocsc())
print("qdldl solve ms", round(tm(lambda: Q.solve(b), 10), 2), "agree", np.abs(Q.solve(b) - x0).max() / np.abs(x0).max())

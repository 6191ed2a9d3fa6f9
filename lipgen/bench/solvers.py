"""Benchmark suite ``solvers``: many right-hand sides with one factorisation (issue 22).

At resolution 4 (about 45,000 nodes; resolution 2 with ``quick``) it times, interleaved round by
round (:func:`lipgen.bench.compare.interleaved`):

* against the CHOLMOD factorisation (cvxopt) of the grounded stiffness: the reach plan for the 16
  markers (48 goal DOFs, ``Physics.reach`` with an empty plan cache: 2 x 48 solves and a QR) and
  one block of 48 right-hand sides. **Target:** the reach plan at most 1.5x the factorisation.
* against cvxopt's column-by-column loop over the same 48 right-hand sides: lipgen's one-call
  block solve, cholespy's block solve and SuperLU's block solve (peers, each with its own
  factor, made outside the timing); with one right-hand side, lipgen against cholespy.
* cholespy's factorisation against cvxopt's.

Each figure is the median over rounds of the per-round ratio of wall times; the load average is
recorded. On a loaded machine wall times swing by 2-3x between rounds, so the peer comparisons
are also given per core (``*_cpu``): CPU-time ratios with BLAS limited to one thread for all.
"""

from __future__ import annotations

import logging
import os

import numpy as np

from lipgen.bench.compare import interleaved, load_average

NAME = "solvers"

log = logging.getLogger(__name__)

TARGETS = {"reach_plan_over_factor": 1.5}


def _solve_with(factor, B):
    return lambda: factor.solve(B)


def _interleaved_cpu(fns: dict, baseline: str, rounds: int) -> dict:
    """Median over rounds of CPU time(name) / CPU time(baseline), one BLAS thread, interleaved."""
    import time

    from lipgen._threads import blas_threads

    times = {name: [] for name in fns}
    with blas_threads(1):
        for fn in fns.values():
            fn()
        for _ in range(rounds):
            for name, fn in fns.items():
                c0 = time.process_time()
                fn()
                times[name].append(time.process_time() - c0)
    base = np.asarray(times[baseline])
    return {name: float(np.median(np.asarray(t) / base)) for name, t in times.items() if name != baseline}


def run(quick: bool = False) -> dict:
    """Figures at resolution 4 (or 2 with ``quick``); empty with a reason without cvxopt."""
    import lipgen
    from lipgen.fem import Physics, cholmod_available
    from lipgen.fem.solver import cholespy_available, factorize

    if not cholmod_available():
        return {"skipped": "cvxopt (CHOLMOD) is not installed: pip install 'lipgen[fast]'"}
    resolution = 2 if quick else 4
    rounds = 3
    mesh = lipgen.lip_mesh(resolution)
    physics = Physics(mesh, solver="cholmod")
    Ks = physics.K_s.tocsc()
    fac = physics._factor
    rng = np.random.default_rng(0)
    d = lipgen.dofs(mesh.markers, "xyz")
    goal = rng.standard_normal(len(d))
    B = rng.standard_normal((Ks.shape[0], len(d)))
    b = np.ascontiguousarray(B[:, 0])
    out: dict = {"resolution": resolution, "nodes": mesh.n_nodes, "free_dofs": Ks.shape[0],
                 "right_hand_sides": len(d), "multi_column": fac.multi_column,
                 "cpu_count": os.cpu_count(), "load_average_before": load_average()}

    def plan():
        physics._plans.clear()
        physics.reach(d, goal)

    t = interleaved({"factor": lambda: factorize(Ks, "cholmod"), "reach_plan": plan,
                     "block_48": _solve_with(fac, B)}, "factor", rounds=rounds)
    out["reach_plan_over_factor"] = t["reach_plan"]["ratio_median"]
    out["block_48_over_factor"] = t["block_48"]["ratio_median"]
    out["factor_s_median"] = t["factor"]["median_s"]

    peers = {"loop_48": lambda: fac._solve_columns(B), "lipgen_48": _solve_with(fac, B),
             "superlu_48": _solve_with(factorize(Ks, "superlu"), B)}
    singles = {"lipgen_1": _solve_with(fac, b)}
    if cholespy_available():
        chol = factorize(Ks, "cholespy")
        peers["cholespy_48"] = _solve_with(chol, B)
        singles["cholespy_1"] = _solve_with(chol, b)
        f = interleaved({"cholmod": lambda: factorize(Ks, "cholmod"),
                         "cholespy": lambda: factorize(Ks, "cholespy")}, "cholmod", rounds=rounds)
        out["cholespy_factor_over_cholmod_factor"] = f["cholespy"]["ratio_median"]
    t = interleaved(peers, "loop_48", rounds=rounds)
    out["over_column_loop_48"] = {k: t[k]["ratio_median"] for k in peers if k != "loop_48"}
    out["loop_48_s_median"] = t["loop_48"]["median_s"]
    t = interleaved(singles, "lipgen_1", rounds=5)
    out["one_rhs_over_lipgen"] = {k: t[k]["ratio_median"] for k in singles if k != "lipgen_1"}
    out["over_column_loop_48_cpu"] = _interleaved_cpu(peers, "loop_48", rounds)
    out["one_rhs_over_lipgen_cpu"] = _interleaved_cpu(singles, "lipgen_1", 5)
    out["load_average_after"] = load_average()
    out["targets"] = TARGETS
    out["meets_targets"] = {"reach_plan_at_most_1.5x_factor":
                            out["reach_plan_over_factor"] <= TARGETS["reach_plan_over_factor"]}
    log.info("solvers bench: %s", out)
    return out

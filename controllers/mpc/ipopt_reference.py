"""The same MPC problem solved by CasADi + IPOPT: the reference for correctness and the timing baseline.

Variables are the tangent increments ``delta`` (13 per block, as in
:mod:`controllers.mpc.manifold`) about a fixed base point ``Z_base``: the blocks
are ``Z_base [+] delta`` with the exact SO(3) exponential, so rotations are
parameterised as increments and the problem is an unconstrained NLP with the
very cost the LM solver minimises (the stage residuals of
:meth:`MPCProblem.residual_function`, summed squared). IPOPT gets exact first
and second derivatives from CasADi (the expression graph is expanded to SX) and
runs to a tight tolerance, so its cost is the optimum the LM solution is judged
against. It is started from the same initial guess as the LM solver.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from controllers.mpc.cost import MPCProblem
from controllers.mpc.manifold import POINT_SIZE, TANGENT_SIZE, boxplus

__all__ = ["IpoptReference", "IpoptResult"]

DEFAULT_OPTIONS = {
    "ipopt.print_level": 0,
    "print_time": False,
    "ipopt.sb": "yes",
    "ipopt.tol": 1e-10,
    "ipopt.acceptable_tol": 1e-8,
    "ipopt.max_iter": 500,
}


@dataclass
class IpoptResult:
    Z: np.ndarray  # (19, N)
    cost: float
    seconds: float  # wall time of the solver call
    iterations: int
    success: bool
    status: str


class IpoptReference:
    """IPOPT on the MPC problem of ``problem`` (same residuals, weights and parameters)."""

    def __init__(self, problem: MPCProblem, options: dict | None = None):
        self.problem = problem
        N = problem.horizon
        delta = ca.SX.sym("delta", TANGENT_SIZE, N)
        Z_base = ca.SX.sym("Z_base", POINT_SIZE, N)
        start = ca.SX.sym("start", POINT_SIZE)
        S = ca.SX.sym("S", problem.stage_size, N)
        g = ca.SX.sym("global", problem.global_size)
        residual = problem.residual_function()
        points = [boxplus(Z_base[:, k], delta[:, k], orthonormalise=False) for k in range(N)]
        cost = 0
        for k in range(N):
            prev = start if k == 0 else points[k - 1]
            cost += ca.sumsqr(residual(prev, points[k], S[:, k], g))
        parameters = ca.vertcat(ca.vec(Z_base), start, ca.vec(S), g)
        nlp = {"x": ca.vec(delta), "p": parameters, "f": cost}
        self.solver = ca.nlpsol("mpc_ipopt", "ipopt", nlp, {**DEFAULT_OPTIONS, **(options or {})})
        self._points = ca.Function("mpc_points", [delta, Z_base], [ca.horzcat(*points)])
        self._n = TANGENT_SIZE * N

    def solve(self, Z_base: np.ndarray, start: np.ndarray, S: np.ndarray, g: np.ndarray) -> IpoptResult:
        """Minimise from ``Z_base`` (``delta = 0``); returns the optimal blocks and cost."""
        p = np.concatenate([np.ravel(Z_base, order="F"), start, np.ravel(S, order="F"), g])
        t0 = time.perf_counter()
        solution = self.solver(x0=np.zeros(self._n), p=p)
        seconds = time.perf_counter() - t0
        stats = self.solver.stats()
        delta = np.asarray(solution["x"]).reshape(TANGENT_SIZE, -1, order="F")
        Z = np.asarray(self._points(delta, Z_base))
        return IpoptResult(Z, float(solution["f"]), seconds, int(stats.get("iter_count", -1)),
                           bool(stats.get("success", False)), str(stats.get("return_status", "")))

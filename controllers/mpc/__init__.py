"""The paper's on-manifold MPC (Sec. 3.3): problem, Levenberg-Marquardt solver, IPOPT reference, policies.

=====================  ==========================================================
module                 what
=====================  ==========================================================
``manifold``           block layout, boxplus/boxminus (CasADi)
``cost``               residual blocks, weights (sigmas), limits, the model's force
``lm``                 compiled Levenberg-Marquardt with block-tridiagonal solves
``ipopt_reference``    the same problem solved by CasADi + IPOPT (tests, benchmark)
``reference``          reference states of the horizon (flatness with the model)
``step``               the whole control step compiled, for a batch in one call
``policy``             :class:`MPC` and :class:`SCMPC`, the SB3-style policies
=====================  ==========================================================
"""

from controllers.mpc.cost import InputLimits, MPCProblem, MPCWeights
from controllers.mpc.lm import LevenbergMarquardt, LMSettings
from controllers.mpc.policy import MPC, SCMPC

__all__ = ["MPC", "SCMPC", "MPCProblem", "MPCWeights", "InputLimits", "LevenbergMarquardt", "LMSettings"]

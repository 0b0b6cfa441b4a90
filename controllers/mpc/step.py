"""The whole MPC control step as one compiled function, evaluated for a batch of vehicles in one call.

Per vehicle, :func:`build_step_function` does what :class:`~controllers.mpc.policy.MPC`
describes (steps 1-3 of its docstring) after the env's reference has been sampled:

0. the measured state ``x_0`` and the reference position from the observation row;
1. the warm start: the previous solution shifted by ``shift`` blocks (its last block
   repeated), or at a cold start the reference states with the flatness thrust and
   zero body rates;
2. the reference states of the horizon (:func:`~controllers.mpc.reference.build_reference_function`,
   the model force at the warm start's predicted states) and the stage parameters;
3. the whole Levenberg-Marquardt solve (:func:`~controllers.mpc.lm.build_solve_function`,
   ``max_iterations_cold`` iterations at a cold start, else ``max_iterations``).

:class:`CompiledStep` compiles it with the batch loop of
:class:`wall_env.codegen.BatchedFunction` (``-O3 -fno-math-errno -march=native``, the
library keyed by the host processor), so ``predict`` on
``n`` observations is one native call that solves the ``n`` problems one after the
other; the single env is ``n = 1``. The generated code depends on the problem
structures, the horizon, the shift and the unrolled iteration count only.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import casadi as ca
import numpy as np

from controllers.mpc.cost import MPCProblem
from controllers.mpc.lm import LMInfo, LMSettings, finite, solve_function
from controllers.mpc.manifold import POINT_SIZE, PointIndex
from controllers.mpc.reference import ReferenceOptions, reference_function
from wall_env.codegen import NATIVE_FLAGS, BatchedFunction
from wall_env.observation import OBSERVATION_FIELDS, OBSERVATION_SIZE

__all__ = ["StepInput", "StepOutput", "StepOptions", "StepStatus", "build_step_function", "cold_start_guess",
           "CompiledStep"]


class StepOptions:
    """Entries of the ``options`` input of :func:`build_step_function`."""

    reference = slice(0, ReferenceOptions.size)  # yaw, max tilt, model attitude, (at prediction: set here)
    force_at_prediction = ReferenceOptions.size
    initial_damping = ReferenceOptions.size + 1
    relative_tolerance = ReferenceOptions.size + 2
    step_tolerance = ReferenceOptions.size + 3
    max_iterations = ReferenceOptions.size + 4
    max_iterations_cold = ReferenceOptions.size + 5
    size = ReferenceOptions.size + 6


class StepInput:
    """Input order of :func:`build_step_function` (``surfaces`` only for a scene with bodies)."""

    Z_previous, cold, observation, samples, global_params, attitude_global, options, surfaces = range(8)


class StepOutput:
    """Output order of :func:`build_step_function`."""

    Z, info, Z0, stage_params, status = range(5)


class StepStatus:
    """Entries of the ``status`` output of :func:`build_step_function`."""

    ok = 0  # 1: a finite observation and a finite solution with a finite cost
    finite_observation = 1
    cold = 2  # the solve started cold (the ``cold`` input)
    size = 3


def cold_start_guess(thrust, p_ref, R_ref, v_ref):
    """The blocks ``(19, N)`` a cold start begins from: the reference states (``p_ref (3, N)``,
    ``R_ref (9, N)`` column-major per matrix, ``v_ref (3, N)``), the flatness thrust ``(1, N)``
    and zero body rates. Symbolic (inside the control step) or numeric (CasADi ``DM``) alike."""
    return ca.vertcat(thrust, ca.DM.zeros(3, thrust.shape[1]), p_ref, R_ref, v_ref)


def build_step_function(problem: MPCProblem, attitude_problem: MPCProblem, shift: int,
                        unrolled: int) -> ca.Function:
    """``mpc_control_step(Z_previous[19xN], cold, observation[48], samples[9x(N+1)], global, attitude_global,
    options) -> (Z[19xN], info[6], Z0[19xN], S[17xN], status[3])``.

    ``observation``: the env's observation (:mod:`wall_env.observation`), from which the
    measured state ``x_0`` and the reference position ``p_ref_now = p_world - p_error``
    are read; ``samples`` as :class:`~controllers.mpc.reference.HorizonSampler`;
    ``global``/``attitude_global`` the global parameters of ``problem`` and of the problem
    whose force enters the attitude reference; ``options`` as :class:`StepOptions`.
    ``info`` as :class:`~controllers.mpc.lm.LMInfo`; ``Z0`` and ``S`` are the initial guess
    and stage parameters the solve started from (a benchmark hands them to IPOPT);
    ``status`` as :class:`StepStatus`.

    For a scene with bodies the function takes one more input, ``surfaces[surface_size x (N+1)]``: the
    rotors' local surfaces at the states ``x_0 .. x_N`` the warm start predicts (the measured state first),
    which the dynamics of stage ``k`` read at ``x_k`` and the attitude reference at ``x_1 .. x_N``.
    """
    N = problem.horizon
    Z_previous = ca.MX.sym("Z_previous", POINT_SIZE, N)
    cold = ca.MX.sym("cold")
    observation = ca.MX.sym("observation", OBSERVATION_SIZE)
    samples = ca.MX.sym("samples", 9, N + 1)
    g = ca.MX.sym("global", problem.global_size)
    g_attitude = ca.MX.sym("attitude_global", attitude_problem.global_size)
    options = ca.MX.sym("options", StepOptions.size)
    surfaces = ca.MX.sym("surfaces", problem.surface_size, N + 1)

    p_world = observation[OBSERVATION_FIELDS["p_world"]]
    # the observation holds R row by row; the blocks hold it column by column
    R_columns = ca.vec(ca.reshape(observation[OBSERVATION_FIELDS["R_body_to_world"]], 3, 3).T)
    x_now = ca.vertcat(p_world, R_columns, observation[OBSERVATION_FIELDS["v_world"]])
    p_ref_now = p_world - observation[OBSERVATION_FIELDS["p_error"]]
    k = min(int(shift), N - 1)
    Z_warm = ca.horzcat(Z_previous[:, k:], ca.repmat(Z_previous[:, N - 1], 1, k))
    at_prediction = (1 - cold) * options[StepOptions.force_at_prediction]
    reference_options = ca.vertcat(options[ReferenceOptions.yaw], options[ReferenceOptions.max_tilt],
                                   options[ReferenceOptions.model_attitude], at_prediction)
    p_ref, v_ref, R_ref, thrust = reference_function(attitude_problem)(
        samples, p_ref_now, Z_warm[PointIndex.p_world, :], Z_warm[PointIndex.v_world, :], g_attitude,
        reference_options, surfaces[:, 1:] if problem.surface_size else ca.MX(0, N))
    S = ca.vertcat(p_ref, v_ref, R_ref, ca.DM(problem.stage_flags()))  # the rows of StageParamIndex
    if problem.surface_size:
        S = ca.vertcat(S, surfaces[:, :N])  # each stage's force at x_k
    Z_cold = cold_start_guess(thrust, p_ref, R_ref, v_ref)
    Z0 = ca.if_else(cold, Z_cold, Z_warm)
    start = ca.vertcat(ca.MX.zeros(4), x_now)  # its input slot is unused
    limit = ca.if_else(cold, options[StepOptions.max_iterations_cold], options[StepOptions.max_iterations])
    lm_settings = ca.vertcat(options[StepOptions.initial_damping], options[StepOptions.relative_tolerance],
                             options[StepOptions.step_tolerance], limit)
    Z, info = solve_function(problem, unrolled)(Z0, start, S, g, lm_settings)
    finite_observation = finite(ca.sum1(observation))
    ok = finite_observation * (1 - info[LMInfo.failed]) * finite(info[LMInfo.cost] + ca.sum1(ca.sum2(Z)))
    inputs = [Z_previous, cold, observation, samples, g, g_attitude, options]
    names = ["Z_previous", "cold", "observation", "samples", "global", "attitude_global", "options"]
    if problem.surface_size:
        inputs.append(surfaces)
        names.append("surfaces")
    return ca.Function("mpc_control_step", inputs, [Z, info, Z0, S, ca.vertcat(ok, finite_observation, cold)],
                       names, ["Z", "info", "Z0", "S", "status"])


class CompiledStep:
    """:func:`build_step_function` compiled for batches: :meth:`resize` binds arrays of ``n`` rows
    (:attr:`inputs`, :attr:`outputs`, one row per vehicle, as :class:`StepInput`/:class:`StepOutput`),
    :meth:`__call__` runs every row in one native call.

    ``threads > 1`` splits the rows into that many contiguous blocks evaluated at once by
    as many threads (native calls release the GIL), for throughput on several cores (training
    on a batched env); each vehicle's numbers are the same.
    """

    def __init__(self, problem: MPCProblem, attitude_problem: MPCProblem, shift: int, settings: LMSettings,
                 threads: int = 1):
        self.function = BatchedFunction(build_step_function(problem, attitude_problem, shift, settings.unrolled),
                                        NATIVE_FLAGS)
        self.threads = int(threads)
        self._pool = ThreadPoolExecutor(self.threads - 1) if self.threads > 1 else None
        self._parts: list[BatchedFunction] = []
        self.inputs: list[np.ndarray] = []
        self.outputs: list[np.ndarray] = []
        self.n = 0

    def resize(self, n: int) -> None:
        """Fresh zero arrays for ``n`` rows (every row must be filled before a call)."""
        self.inputs = [np.zeros((n, k)) for k in self.function.nnz_in]
        self.outputs = self.function.outputs(n)
        blocks = [rows for rows in np.array_split(np.arange(n), min(self.threads, n)) if len(rows)]
        self._parts = [self.function] + [self.function.clone() for _ in blocks[1:]]
        for part, rows in zip(self._parts, blocks):
            rows_slice = slice(int(rows[0]), int(rows[-1]) + 1)
            part.bind([a[rows_slice] for a in self.inputs], [a[rows_slice] for a in self.outputs])
        self.n = n

    def __call__(self) -> None:
        if len(self._parts) == 1 or self._pool is None:
            self._parts[0]()
            return
        others = [self._pool.submit(part) for part in self._parts[1:]]
        self._parts[0]()
        for job in others:
            job.result()

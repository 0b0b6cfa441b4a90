/* Wall Inspector: an exported MPC or SC-MPC control step, C99, no allocation, no Python.
 *
 * One call of wi_step per control step (WI_CONTROL_DT seconds) computes what the Python
 * controller's predict() computes: the warm start, the reference states of the horizon,
 * the Levenberg-Marquardt solve with the prediction model (the suction effect included
 * for SC-MPC), the first input of the solution as the command, and the hover fallback
 * when there is no usable solution.
 *
 * In
 *   observation[WI_OBSERVATION_SIZE]  the env's observation, SI units (wall_env/observation.py):
 *                                     p_world 0-2, v_world 3-5, R_body_to_world 6-14 (row by row),
 *                                     p_error = p_world - p_ref(t) 18-20, time (s) 47; the
 *                                     controller reads these entries only.
 *   samples[WI_SAMPLES_SIZE]          the reference at t + k WI_DT for k = 0 .. WI_HORIZON
 *                                     (t = the observation's time): for each k the nine numbers
 *                                     p (m), v (m/s), a (m/s^2), world frame. Only differences
 *                                     of p matter (the horizon is anchored at p_world - p_error).
 *   parameters                        the per-controller numbers; wi_default_parameters gives the
 *                                     ones it was exported with (export.json lists them by name).
 * In and out
 *   memory                            the solution kept for the next call's warm start, and the
 *                                     solver's work arrays: one wi_memory per vehicle, set up by
 *                                     wi_memory_init and again at every episode (flight) start.
 * Out
 *   command[4]                        [T (N), wx, wy, wz (rad/s, body frame)]: collective thrust
 *                                     and body rates, as the MPC solved them (not clipped).
 *   action[4]                         the command as the env's normalised action, in [-1, 1].
 * Returns WI_OK, or a failure code; after a failure the command is the hover fallback (thrust
 * m g, body rates that level the vehicle, zero rates if the attitude is unknown) and the next
 * call starts cold, exactly as the Python controller does.
 *
 * A time that goes backwards also starts a new episode (as predict() does without
 * episode_start). The memory holds about 8 * (WI_WORK_SIZE + 3 WI_BLOCKS_SIZE) bytes: make it
 * static or allocate it once, not on a small stack. wi_step is reentrant for distinct memories.
 */
#ifndef WI_CONTROLLER_H
#define WI_CONTROLLER_H

#include "wi_config.h" /* generated: the sizes of this controller */

#ifdef __cplusplus
extern "C" {
#endif

enum {
  WI_OK = 0,
  WI_NONFINITE_OBSERVATION = 1, /* a NaN or infinity in the observation */
  WI_SOLVER_FAILURE = 2,        /* a non-finite cost at the initial guess */
  WI_NONFINITE_SOLUTION = 3     /* the solve ended on non-finite numbers */
};

/* Every field is a double, in this order (the Python side packs the same layout). */
typedef struct {
  double global[WI_GLOBAL_SIZE];                   /* the problem's global parameters (dt, mass, weights,
                                                      limits, model parameters, walls) */
  double attitude_global[WI_ATTITUDE_GLOBAL_SIZE]; /* the same for the model of the attitude reference */
  double options[WI_OPTIONS_SIZE];                 /* yaw of the reference (rad), tilt limit, solver settings */
  double thrust_hover;                             /* N: the action mapping ... */
  double thrust_max;                               /* N */
  double body_rate_max;                            /* rad/s */
  double fallback_mass;                            /* kg: hover fallback thrust is fallback_mass * g */
  double fallback_body_rate_max;                   /* rad/s: limit of the fallback's levelling rates */
} wi_parameters;

typedef struct {
  double Z_previous[WI_BLOCKS_SIZE]; /* the previous solution, blocks (u_k, x_k+1), column by column */
  double cold;                       /* 1: the next call starts from the reference (cold start) */
  double last_time;                  /* s: the latest finite observation time */
  double Z[WI_BLOCKS_SIZE];          /* this call's solution */
  double info[WI_INFO_SIZE];         /* cost, initial cost, iterations, accepted, converged, failed */
  double status[WI_STATUS_SIZE];     /* ok, finite observation, cold */
  double w[WI_WORK_SIZE];            /* the solver's work arrays */
  long long iw[WI_INT_WORK_SIZE];
} wi_memory;

/* The parameters the controller was exported with (export.json names each entry). */
void wi_default_parameters(wi_parameters *parameters);

/* A fresh memory: the next call starts cold. Call it once per vehicle and at every episode start. */
void wi_memory_init(wi_memory *memory);

/* One control step; see the top of this file. */
int wi_step(const double *observation, const double *samples, const wi_parameters *parameters,
            wi_memory *memory, double *command, double *action);

/* Sizes this library was built with, for callers that check them (ctypes, other languages):
 * observation, samples, global, attitude_global, options, horizon, sizeof(wi_parameters),
 * sizeof(wi_memory). */
void wi_sizes(long long sizes[8]);

#ifdef __cplusplus
}
#endif
#endif

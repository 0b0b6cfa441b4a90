/* Wall Inspector: the entry point of an exported MPC or SC-MPC (see wi_controller.h).
 *
 * The numbers come from two functions CasADi generated into wi_casadi.c: mpc_control_step
 * (controllers/mpc/step.py: warm start, reference states, Levenberg-Marquardt solve) and
 * wi_hover_command (the hover fallback of controllers/policy.py). This file only keeps the
 * memory between calls, maps the command to the normalised action and picks the fallback.
 */
#include <math.h>
#include <string.h>

#include "wi_casadi.h"
#include "wi_controller.h"

static int all_finite(const double *x, int n) {
  int i;
  for (i = 0; i < n; ++i)
    if (!isfinite(x[i])) return 0;
  return 1;
}

static double clip(double x, double low, double high) { return x < low ? low : (x > high ? high : x); }

void wi_memory_init(wi_memory *memory) {
  memset(memory->Z_previous, 0, sizeof memory->Z_previous);
  memory->cold = 1.0;
  memory->last_time = -INFINITY;
}

static int solve(const double *observation, const double *samples, const wi_parameters *p, wi_memory *m) {
  const double *arg[WI_ARG_SIZE] = {0};
  double *res[WI_RES_SIZE] = {0};
  arg[0] = m->Z_previous;
  arg[1] = &m->cold;
  arg[2] = observation;
  arg[3] = samples;
  arg[4] = p->global;
  arg[5] = p->attitude_global;
  arg[6] = p->options;
  res[0] = m->Z;
  res[1] = m->info;
  res[4] = m->status; /* the initial guess and stage parameters (outputs 2, 3) are not needed */
  if (mpc_control_step(arg, res, m->iw, m->w, 0)) return WI_SOLVER_FAILURE;
  if (m->status[0] != 0.0) return WI_OK;
  if (m->status[1] == 0.0) return WI_NONFINITE_OBSERVATION;
  return m->info[5] != 0.0 ? WI_SOLVER_FAILURE : WI_NONFINITE_SOLUTION;
}

static void hover(const double *observation, const wi_parameters *p, wi_memory *m, double *command) {
  const double *arg[WI_ARG_SIZE] = {0};
  double *res[WI_RES_SIZE] = {0};
  arg[0] = observation + WI_OBS_R;
  arg[1] = &p->fallback_mass;
  arg[2] = &p->fallback_body_rate_max;
  res[0] = command;
  wi_hover_command(arg, res, m->iw, m->w, 0);
}

int wi_step(const double *observation, const double *samples, const wi_parameters *parameters,
            wi_memory *memory, double *command, double *action) {
  const double time = observation[WI_OBS_TIME];
  int status, i;
  if (time < memory->last_time) memory->cold = 1.0; /* time went back: a new episode */
  if (isfinite(time)) memory->last_time = time;
  status = all_finite(observation, WI_OBSERVATION_SIZE) ? solve(observation, samples, parameters, memory)
                                                         : WI_NONFINITE_OBSERVATION;
  if (status == WI_OK) {
    memcpy(memory->Z_previous, memory->Z, sizeof memory->Z);
    memory->cold = 0.0;
    for (i = 0; i < 4; ++i) command[i] = memory->Z[i]; /* u_0 */
  } else {
    hover(observation, parameters, memory, command);
    memory->cold = 1.0;
  }
  /* the env's action mapping (wall_env/actions.py, ActionMapping.to_normalised) */
  action[0] = clip((command[0] - parameters->thrust_hover) / (parameters->thrust_max - parameters->thrust_hover), -1.0, 1.0);
  for (i = 1; i < 4; ++i) action[i] = clip(command[i] / parameters->body_rate_max, -1.0, 1.0);
  return status;
}

void wi_sizes(long long sizes[8]) {
  sizes[0] = WI_OBSERVATION_SIZE;
  sizes[1] = WI_SAMPLES_SIZE;
  sizes[2] = WI_GLOBAL_SIZE;
  sizes[3] = WI_ATTITUDE_GLOBAL_SIZE;
  sizes[4] = WI_OPTIONS_SIZE;
  sizes[5] = WI_HORIZON;
  sizes[6] = (long long)sizeof(wi_parameters);
  sizes[7] = (long long)sizeof(wi_memory);
}

/* Wall Inspector: a C timing loop over recorded control steps of an exported controller.
 *
 *   wi_bench PROBLEMS RESULTS [PASSES]
 *
 * PROBLEMS (raw little-endian doubles, written by controllers/export/timing.py): a header
 * [count, WI_OBSERVATION_SIZE, WI_SAMPLES_SIZE, parameter doubles], then per step
 * [episode start (0/1), observation, samples, parameters]. The steps are run in order, once
 * untimed (to warm the caches) and then PASSES times (default 5), each wi_step call timed
 * alone with the monotonic clock (wall) and the thread's CPU clock (which other processes
 * taking the core cannot inflate). RESULTS: [count, PASSES], per step of the last pass
 * [status, command (4), action (4), LM iterations, cold start (0/1)], then every timed call's wall seconds
 * (PASSES x count), then its CPU seconds (PASSES x count).
 */
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "wi_controller.h"

#define PARAMETER_SIZE ((long)(sizeof(wi_parameters) / sizeof(double)))
#define RECORD_SIZE (1 + WI_OBSERVATION_SIZE + WI_SAMPLES_SIZE + PARAMETER_SIZE)

#define OUTPUT_SIZE 11

static double now(clockid_t clock) {
  struct timespec t;
  clock_gettime(clock, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static int fail(const char *message) {
  fprintf(stderr, "wi_bench: %s\n", message);
  return 2;
}

int main(int argc, char **argv) {
  FILE *file;
  double header[4], *records, *outputs, *seconds, *cpu_seconds;
  long count, passes = 5, pass, k;
  static wi_memory memory;
  wi_parameters parameters;
  if (argc < 3 || argc > 4) return fail("usage: wi_bench PROBLEMS RESULTS [PASSES]");
  if (argc == 4 && (passes = strtol(argv[3], NULL, 10)) < 1) return fail("PASSES must be a positive integer");
  if (!(file = fopen(argv[1], "rb"))) return fail("cannot open PROBLEMS");
  if (fread(header, sizeof(double), 4, file) != 4) return fail("PROBLEMS has no header");
  count = (long)header[0];
  if (count < 1 || header[1] != WI_OBSERVATION_SIZE || header[2] != WI_SAMPLES_SIZE || header[3] != PARAMETER_SIZE)
    return fail("PROBLEMS was recorded for a controller of other sizes");
  records = malloc(sizeof(double) * RECORD_SIZE * (size_t)count);
  outputs = malloc(sizeof(double) * OUTPUT_SIZE * (size_t)count);
  seconds = malloc(sizeof(double) * (size_t)(passes * count));
  cpu_seconds = malloc(sizeof(double) * (size_t)(passes * count));
  if (!records || !outputs || !seconds || !cpu_seconds) return fail("out of memory");
  if (fread(records, sizeof(double), (size_t)(RECORD_SIZE * count), file) != (size_t)(RECORD_SIZE * count))
    return fail("PROBLEMS is shorter than its header says");
  fclose(file);

  for (pass = 0; pass <= passes; ++pass) {
    wi_memory_init(&memory);
    for (k = 0; k < count; ++k) {
      const double *record = records + RECORD_SIZE * k;
      const double *observation = record + 1, *samples = observation + WI_OBSERVATION_SIZE;
      double command[4], action[4], start, cpu_start;
      int status;
      if (record[0] != 0.0) wi_memory_init(&memory);
      memcpy(&parameters, samples + WI_SAMPLES_SIZE, sizeof parameters);
      cpu_start = now(CLOCK_THREAD_CPUTIME_ID);
      start = now(CLOCK_MONOTONIC);
      status = wi_step(observation, samples, &parameters, &memory, command, action);
      if (pass > 0) {
        seconds[(pass - 1) * count + k] = now(CLOCK_MONOTONIC) - start;
        cpu_seconds[(pass - 1) * count + k] = now(CLOCK_THREAD_CPUTIME_ID) - cpu_start;
      }
      if (pass == passes) {
        double *out = outputs + OUTPUT_SIZE * k;
        out[0] = status;
        memcpy(out + 1, command, sizeof command);
        memcpy(out + 5, action, sizeof action);
        out[9] = memory.info[2];
        out[10] = memory.status[2];
      }
    }
  }

  if (!(file = fopen(argv[2], "wb"))) return fail("cannot write RESULTS");
  header[0] = (double)count;
  header[1] = (double)passes;
  fwrite(header, sizeof(double), 2, file);
  fwrite(outputs, sizeof(double), (size_t)(OUTPUT_SIZE * count), file);
  fwrite(seconds, sizeof(double), (size_t)(passes * count), file);
  fwrite(cpu_seconds, sizeof(double), (size_t)(passes * count), file);
  fclose(file);
  free(records);
  free(outputs);
  free(seconds);
  free(cpu_seconds);
  return 0;
}

/* The unity build a package makes of the runtime: CHAINGEN_LINKAGE static and the source
 * included, so nothing but the package's own API is exported. Compiled with the strict flags
 * (-Wall -Wextra -Werror -pedantic), it checks that the runtime builds this way without a
 * warning: every public function is called below, so an unused static function would be one the
 * runtime defines but never uses. Runs a few calls on the pendulum and exits 0 when they work.
 *
 *     cc -std=c99 -Wall -Wextra -Werror -pedantic -O2 -I.. unity_build.c pendulum_model.c -lm */
#define CHAINGEN_LINKAGE static
#include "chaingen_runtime.c"

#include <stdio.h>

#include "pendulum_model.h"

typedef struct {
    chaingen_workspace_scalars scalars;
    const double *arg[PENDULUM_ARG];
    double *res[PENDULUM_RES];
    long long int iw[PENDULUM_IW];
    double w[PENDULUM_W];
    int ints[CHAINGEN_WORKSPACE_INTS(PENDULUM_NZ, 0)];
    double doubles[CHAINGEN_WORKSPACE_DOUBLES(PENDULUM_N, PENDULUM_NX, PENDULUM_NZ, 1, 1, 1, 0,
                                              0, 1, 0, 1, PENDULUM_NCONSTRAINT)];
} unity_workspace;

static unity_workspace storage;

static int controller(long step, double t, const double *phi, const double *omega, double *u,
                      void *context)
{
    (void)step, (void)t, (void)omega, (void)context;
    u[0] = -phi[0];
    return 0;
}

static int observer(long steps, void *context)
{
    (void)steps, (void)context;
    return 0;
}

int main(void)
{
    pendulum_variant variant;
    chaingen_model model;
    chaingen_workspace ws;
    chaingen_options options;
    chaingen_stats stats;
    chaingen_control control = {0, 0};
    const double p[1] = {PENDULUM_STIFFNESS}, u[1] = {0.1}, phi[1] = {0.5}, rate[1] = {0.0};
    double x0[2], x1[2], flows[2], tau, energy, error, wrapped, omega, f[2], jacobian[4];
    double ds[4], du[2], dp[2], samples[7 * 11], torques[10];
    int iterations, failures = 0;
    memset(&variant, 0, sizeof variant);
    variant.actuated = variant.parameters = variant.damped = variant.flows = 1;
    variant.segments = variant.energy_check = variant.sensitivities = variant.holding = 1;
    variant.control = 1;
    pendulum_model_init(&model, &variant);
    ws.scalars = &storage.scalars;
    ws.arg = storage.arg;
    ws.res = storage.res;
    ws.iw = storage.iw;
    ws.w = storage.w;
    ws.ints = storage.ints;
    ws.doubles = storage.doubles;
    failures += chaingen_workspace_doubles(&model)
                != (long)(sizeof storage.doubles / sizeof(double));
    failures += chaingen_workspace_ints(&model) != (long)(sizeof storage.ints / sizeof(int));
    failures += chaingen_dimension(&model, CHAINGEN_DIMENSION_NX) != PENDULUM_NX;
    chaingen_workspace_init(&model, &ws);
    chaingen_default_options(&model, &options);
    failures += chaingen_initial_state(&model, phi, rate, p, 1, x0, &ws) != CHAINGEN_OK;
    failures += chaingen_outputs(&model, x0, p, 1, &wrapped, &omega, &energy, &error, &ws)
                != CHAINGEN_OK;
    failures += chaingen_holding_torques(&model, phi, p, 1, &tau, &ws) != CHAINGEN_OK;
    failures += chaingen_residual(&model, rate, x0, u, 1, p, 1, 0.01, f, &ws) != CHAINGEN_OK;
    failures += chaingen_residual_jacobian(&model, rate, x0, u, 1, p, 1, 0.01, f, jacobian, &ws)
                != CHAINGEN_OK;
    failures += chaingen_step(&model, x0, u, 1, p, 1, 0.01, x1, flows, &options, &ws,
                              &iterations) != CHAINGEN_OK;
    failures += chaingen_step_sensitivities(&model, x0, u, 1, p, 1, 0.01, x1, ds, du, dp,
                                            &options, &ws, &iterations) != CHAINGEN_OK;
    failures += chaingen_control_torques(&model, x0, u, 1, p, 1, 0.01, &tau, x1, &options, &ws,
                                         &iterations) != CHAINGEN_OK;
    failures += chaingen_sample_count(&model, 10, 1) != 11;
    failures += chaingen_simulate_observed(&model, x0, 0.0, 0.01, 10, 1, NULL, 1, p, 1, &options,
                                           &ws, samples, x1, &stats, observer, NULL, 1, &control)
                != CHAINGEN_OK;
    failures += chaingen_simulate_controlled(&model, x0, 0.0, 0.01, 10, 1, controller, NULL, 1, p,
                                             1, &options, &ws, samples, torques, x1, &stats,
                                             &control) != CHAINGEN_OK;
    printf("%s\n", failures ? "FAIL unity_build" : "ok unity_build");
    return failures ? 1 : 0;
}

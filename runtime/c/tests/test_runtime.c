/* The C runtime's own tests: the pendulum of pendulum_model.c drives every entry point of
 * chaingen_runtime.c, without SymPy or CasADi.
 *
 * Each group prints "ok <name>" or one "FAIL <name>: detail" line per failed check; the exit
 * status is nonzero when any check failed. `test_runtime NAME...` runs the named groups only.
 *
 * Build (from runtime/c/tests; `make` does it):
 *     cc -std=c99 -Wall -Wextra -Werror -pedantic -O2 -I.. test_runtime.c pendulum_model.c \
 *        ../chaingen_runtime.c -lm -o test_runtime */
#include <float.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "chaingen_runtime.h"
#include "pendulum_model.h"

/* ---- The workspace --------------------------------------------------------------------------- */

/* The workspace of the model in use: the scalars and the function tables in a struct, the
 * doubles and ints on the heap, allocated by use() at exactly chaingen_workspace_doubles/ints of
 * the model, plus GUARD entries set to a sentinel: a carve beyond the formula's size writes them
 * (checked after every group) and, built with -DTEST_GUARD=0 for valgrind and the sanitizers,
 * any access beyond it is an error those report. Heap and not zeroed: memcheck sees a read of
 * anything workspace_init did not set. MAX_DOUBLES and MAX_INTS, the formula at the largest
 * variant's sizes (actuated, a parameter, 9 stages, sensitivities chained in x, a segment),
 * bound every variant's. */
#ifndef TEST_GUARD
#define TEST_GUARD 16
#endif
#define GUARD TEST_GUARD
#define GUARD_DOUBLE 123456.789
#define GUARD_INT 0x5a5a5a5a
#define MAX_DOUBLES                                                                              \
    CHAINGEN_WORKSPACE_DOUBLES(PENDULUM_N, PENDULUM_NX, PENDULUM_NZ, PENDULUM_MAX_NU,             \
                               PENDULUM_MAX_NP, PENDULUM_MAX_NQ, PENDULUM_MAX_NSTAGE, 0, 1, 1, \
                               1, PENDULUM_NCONSTRAINT)
#define MAX_INTS CHAINGEN_WORKSPACE_INTS(PENDULUM_NZ, PENDULUM_MAX_NSTAGE)

typedef struct {
    chaingen_workspace_scalars scalars;
    const double *arg[PENDULUM_ARG];
    double *res[PENDULUM_RES];
    long long int iw[PENDULUM_IW];
    double w[PENDULUM_W];
    int *ints;          /* chaingen_workspace_ints(&model) + GUARD */
    double *doubles;    /* chaingen_workspace_doubles(&model) + GUARD */
} storage;

static chaingen_model model;
static storage *store;
static chaingen_workspace ws;

static chaingen_workspace view(storage *s)
{
    chaingen_workspace v;
    v.scalars = &s->scalars;
    v.arg = s->arg;
    v.res = s->res;
    v.iw = s->iw;
    v.w = s->w;
    v.ints = s->ints;
    v.doubles = s->doubles;
    return v;
}

/* The arrays of a storage for the model in use (uninitialised). 0: out of memory. */
static int allocate(storage *s)
{
    free(s->ints);
    free(s->doubles);
    s->ints = (int *)malloc(sizeof(int) * (size_t)(chaingen_workspace_ints(&model) + GUARD));
    s->doubles = (double *)malloc(sizeof(double)
                                  * (size_t)(chaingen_workspace_doubles(&model) + GUARD));
    return s->ints && s->doubles;
}

/* ---- Reporting ------------------------------------------------------------------------------- */

static const char *group = "";
static int group_failures, total_failures;
static int seen[CHAINGEN_UNAVAILABLE + 1];   /* statuses a check saw produced as expected */

static void failf(int line, const char *format, ...)
{
    va_list args;
    ++group_failures;
    ++total_failures;
    if (group_failures > 12) {
        return;
    }
    printf("FAIL %s: ", group);
    va_start(args, format);
    vprintf(format, args);
    va_end(args);
    printf(" (line %d)\n", line);
}

#define EXPECT(condition, ...)                                                                 \
    do {                                                                                       \
        if (!(condition)) {                                                                    \
            failf(__LINE__, __VA_ARGS__);                                                      \
        }                                                                                      \
    } while (0)

static void expect_status(int got, int want, int line, const char *call)
{
    if (got == want && got >= 0 && got <= CHAINGEN_UNAVAILABLE) {
        seen[got] = 1;
    }
    if (got != want) {
        failf(line, "%.90s: status %d, expected %d", call, got, want);
    }
}

#define STATUS(call, want) expect_status((call), (want), __LINE__, #call)

static int close_to(double a, double b, double tolerance)
{
    return fabs(a - b) <= tolerance;
}

/* ---- Variants -------------------------------------------------------------------------------- */

/* Everything on, one step of the scheme. */
static pendulum_variant full_variant(void)
{
    pendulum_variant v;
    memset(&v, 0, sizeof v);
    v.actuated = 1;
    v.parameters = 1;
    v.damped = 1;
    v.flows = 1;
    v.segments = 1;
    v.energy_check = 1;
    v.sensitivities = 1;
    v.holding = 1;
    return v;
}

/* Nothing optional: no inputs, parameters, flows, segments, energy check or sensitivities. */
static pendulum_variant bare_variant(void)
{
    pendulum_variant v;
    memset(&v, 0, sizeof v);
    return v;
}

static void set_guards(void)
{
    long doubles = chaingen_workspace_doubles(&model), ints = chaingen_workspace_ints(&model);
    int i;
    for (i = 0; i < GUARD; ++i) {
        store->doubles[doubles + i] = GUARD_DOUBLE;
        store->ints[ints + i] = GUARD_INT;
    }
}

static void check_guards(int line)
{
    long doubles = chaingen_workspace_doubles(&model), ints = chaingen_workspace_ints(&model);
    int i;
    for (i = 0; i < GUARD; ++i) {
        if (store->doubles[doubles + i] != GUARD_DOUBLE || store->ints[ints + i] != GUARD_INT) {
            failf(line, "workspace written beyond its formula's size (entry %d after it)", i);
            return;
        }
    }
}

/* Make the variant the model in use, on a fresh workspace. */
static void use(pendulum_variant variant)
{
    pendulum_model_init(&model, &variant);
    if (chaingen_workspace_doubles(&model) > MAX_DOUBLES
        || chaingen_workspace_ints(&model) > MAX_INTS) {
        failf(__LINE__, "the model's workspace (%ld doubles, %ld ints) exceeds the formula at "
              "the largest sizes", chaingen_workspace_doubles(&model),
              chaingen_workspace_ints(&model));
    }
    if (!allocate(store)) {
        printf("FAIL %s: out of memory\n", group);
        exit(2);
    }
    ws = view(store);
    chaingen_workspace_init(&model, &ws);
    set_guards();
}

static void begin(const char *name)
{
    group = name;
    group_failures = 0;
}

static void end(void)
{
    check_guards(__LINE__);
    if (group_failures == 0) {
        printf("ok %s\n", group);
    } else if (group_failures > 12) {
        printf("FAIL %s: %d more failures\n", group, group_failures - 12);
    }
    fflush(stdout);
}

/* ---- Calls at the model's sizes -------------------------------------------------------------- */

static const double STIFFNESS[1] = {PENDULUM_STIFFNESS};

/* u and p for the model in use (NULL when it has none). */
static const double *params(void)
{
    return model.np ? STIFFNESS : NULL;
}

static int step(const double *x0, double tau, double dt, double *x1, double *flows,
                const chaingen_options *options, int *iterations)
{
    const double u[1] = {tau};
    return chaingen_step(&model, x0, model.nu ? u : NULL, model.nu, params(), model.np, dt, x1,
                         flows, options, &ws, iterations);
}

static int simulate(const double *x0, double t0, double dt, long n_steps, long every,
                    const double *u, const chaingen_options *options, double *samples,
                    double *x_final, chaingen_stats *stats)
{
    return chaingen_simulate_observed(&model, x0, t0, dt, n_steps, every, u, model.nu, params(),
                                      model.np, options, &ws, samples, x_final, stats, NULL, NULL,
                                      1, NULL);
}

/* Newton options tight enough for differences and orders: the solutions at round-off. */
static chaingen_options tight(void)
{
    chaingen_options options;
    chaingen_default_options(&model, &options);
    options.update_rtol = 1e-14;
    options.update_atol = 1e-16;
    options.residual_tol = 1e-13;
    options.max_iterations = 50;
    return options;
}

/* ---- Groups ---------------------------------------------------------------------------------- */

static void test_sizes(void)
{
    static const int compositions[4] = {PENDULUM_PLAIN, PENDULUM_YOSHIDA4, PENDULUM_SUZUKI4,
                                        PENDULUM_KAHAN_LI6};
    static const int nstages[4] = {0, 3, 5, 9};
    int a, b, c, s, chain, segments;
    begin("sizes");
    for (segments = 0; segments < 2; ++segments) {
    for (a = 0; a < 2; ++a) {
        for (b = 0; b < 2; ++b) {
            for (c = 0; c < 2; ++c) {
                for (s = 0; s < 4; ++s) {
                    for (chain = 0; chain < 2; ++chain) {
                        pendulum_variant v = bare_variant();
                        long doubles, ints;
                        v.actuated = a;
                        v.parameters = b;
                        v.sensitivities = c;
                        v.chain_state = chain;
                        v.composition = compositions[s];
                        v.segments = segments;
                        use(v);
                        doubles = CHAINGEN_WORKSPACE_DOUBLES(
                            PENDULUM_N, PENDULUM_NX, PENDULUM_NZ, a, b, b, nstages[s], 0, c,
                            chain, segments, PENDULUM_NCONSTRAINT);
                        ints = CHAINGEN_WORKSPACE_INTS(PENDULUM_NZ, nstages[s]);
                        EXPECT(chaingen_workspace_doubles(&model) == doubles,
                               "workspace_doubles %ld, the formula %ld (nu %d np %d sens %d "
                               "nstage %d chain %d)", chaingen_workspace_doubles(&model), doubles,
                               a, b, c, nstages[s], chain);
                        EXPECT(chaingen_workspace_ints(&model) == ints,
                               "workspace_ints %ld, the formula %ld",
                               chaingen_workspace_ints(&model), ints);
                        EXPECT(doubles <= MAX_DOUBLES && ints <= MAX_INTS,
                               "storage too small");
                    }
                }
            }
        }
    }
    }
    end();
}

static void test_dimension(void)
{
    pendulum_variant v = full_variant();
    begin("dimension");
    use(v);
    EXPECT(chaingen_dimension(&model, -1) == -1, "dimension(-1) = %ld",
           chaingen_dimension(&model, -1));
    EXPECT(chaingen_dimension(&model, 100000) == -1, "dimension(100000) = %ld",
           chaingen_dimension(&model, 100000));
    EXPECT(chaingen_dimension(&model, INT_MIN) == -1, "dimension(INT_MIN) = %ld",
           chaingen_dimension(&model, INT_MIN));
    EXPECT(chaingen_dimension(&model, CHAINGEN_DIMENSION_N_JOINTS) == PENDULUM_N, "n_joints");
    EXPECT(chaingen_dimension(&model, CHAINGEN_DIMENSION_NX) == PENDULUM_NX, "nx");
    EXPECT(chaingen_dimension(&model, CHAINGEN_DIMENSION_NZ) == PENDULUM_NZ, "nz");
    EXPECT(chaingen_dimension(&model, CHAINGEN_DIMENSION_NU) == 1, "nu");
    EXPECT(chaingen_dimension(&model, CHAINGEN_DIMENSION_NP) == 1, "np");
    EXPECT(chaingen_dimension(&model, CHAINGEN_DIMENSION_NSAMPLE) == 7, "nsample");
    EXPECT(chaingen_dimension(&model, CHAINGEN_DIMENSION_NCONSTRAINT) == PENDULUM_NCONSTRAINT,
           "nconstraint");
    EXPECT(chaingen_dimension(&model, CHAINGEN_DIMENSION_ORDER) == 2, "order");
    EXPECT(chaingen_dimension(&model, CHAINGEN_DIMENSION_NSTAGE) == 0, "nstage");
    EXPECT(chaingen_dimension(&model, CHAINGEN_DIMENSION_SENSITIVITIES) == 1, "sensitivities");
    EXPECT(chaingen_dimension(&model, CHAINGEN_DIMENSION_SENSITIVITIES + 1) == -1,
           "the first unknown which");
    v.composition = PENDULUM_KAHAN_LI6;
    v.sensitivities = 0;
    use(v);
    EXPECT(chaingen_dimension(&model, CHAINGEN_DIMENSION_ORDER) == 6
               && chaingen_dimension(&model, CHAINGEN_DIMENSION_NSTAGE) == 9
               && chaingen_dimension(&model, CHAINGEN_DIMENSION_SENSITIVITIES) == 0,
           "order, nstage, sensitivities of a composed model without sensitivities");
    use(bare_variant());
    EXPECT(chaingen_dimension(&model, CHAINGEN_DIMENSION_NU) == 0, "nu of the bare model");
    EXPECT(chaingen_dimension(&model, CHAINGEN_DIMENSION_NP) == 0, "np of the bare model");
    EXPECT(chaingen_dimension(&model, CHAINGEN_DIMENSION_NSAMPLE) == 5,
           "nsample of the bare model (no flows)");
    end();
}

static void test_default_options(void)
{
    chaingen_options options;
    begin("default_options");
    use(full_variant());
    memset(&options, 0xff, sizeof options);
    chaingen_default_options(&model, &options);
    EXPECT(options.max_iterations == 20 && options.update_rtol == 1e-10
               && options.update_atol == 1e-13 && options.residual_tol == 1e-8
               && options.warm_start == 1
               && options.reuse_jacobian == CHAINGEN_JACOBIAN_EVERY_ITERATE
               && options.energy_tol == 0.01 && options.rtol == 0.0 && options.atol == 0.0,
           "default_options are not the model's defaults");
    chaingen_default_options(&model, NULL);   /* NULL: nothing */
    end();
}

static void test_workspace_init(void)
{
    long i, doubles, ints;
    const chaingen_workspace_scalars *s;
    begin("workspace_init");
    use(full_variant());
    memset(&store->scalars, 0xff, sizeof store->scalars);
    memset(store->ints, 0xff, sizeof(int) * (size_t)chaingen_workspace_ints(&model));
    memset(store->doubles, 0xff, sizeof(double) * (size_t)chaingen_workspace_doubles(&model));
    memset(store->arg, 0xff, sizeof store->arg);
    memset(store->res, 0xff, sizeof store->res);
    chaingen_workspace_init(&model, &ws);
    s = &store->scalars;
    EXPECT(s->previous_dt == 0.0 && s->factors_dt == 0.0 && s->proposed_dt == 0.0
               && s->previous_error == 0.0 && s->composed_dt == 0.0 && s->energy_ends[0] == 0.0
               && s->energy_ends[1] == 0.0 && s->step_fallbacks == 0 && s->step_splits == 0
               && s->history == 0 && s->warm_choice == 0 && s->chained == 0
               && s->factors_valid == 0 && s->refresh_first == 0 && s->energy_valid == 0
               && s->q_valid == 0
               && s->composed_valid == 0,
           "a scalar of the workspace is not zero after workspace_init");
    doubles = chaingen_workspace_doubles(&model);
    ints = chaingen_workspace_ints(&model);
    for (i = 0; i < doubles; ++i) {
        if (store->doubles[i] != 0.0) {
            failf(__LINE__, "doubles[%ld] not zeroed", i);
            break;
        }
    }
    for (i = 0; i < ints; ++i) {
        if (store->ints[i] != 0) {
            failf(__LINE__, "ints[%ld] not zeroed", i);
            break;
        }
    }
    end();
}

static void test_sample_count(void)
{
    begin("sample_count");
    use(full_variant());
    EXPECT(chaingen_sample_count(&model, -1, 1) == 0, "n_steps < 0");
    EXPECT(chaingen_sample_count(&model, 10, 0) == 0, "every 0");
    EXPECT(chaingen_sample_count(&model, 10, -3) == 0, "every < 0");
    EXPECT(chaingen_sample_count(&model, 0, 1) == 1, "no step: one row");
    EXPECT(chaingen_sample_count(&model, 0, 7) == 1, "no step, every 7: one row");
    EXPECT(chaingen_sample_count(&model, 10, 1) == 11, "10 steps: 11 rows");
    EXPECT(chaingen_sample_count(&model, 10, 3) == 4, "10 every 3: 4 rows");
    EXPECT(chaingen_sample_count(&model, 9, 3) == 4, "9 every 3: 4 rows");
    EXPECT(chaingen_sample_count(&model, 2, 3) == 1, "2 every 3: 1 row");
    EXPECT(chaingen_sample_count(&model, LONG_MAX, 1) == -1, "LONG_MAX rows: -1");
    EXPECT(chaingen_sample_count(&model, LONG_MAX, LONG_MAX) == 2, "LONG_MAX every LONG_MAX: 2");
    EXPECT(chaingen_sample_count(&model, LONG_MAX / 2, 2) == -1, "too many rows: -1");
    {
        /* Rows times NSAMPLE at the edge of LONG_MAX: the largest count that fits. */
        long rows = LONG_MAX / model.nsample - 1;
        long count = chaingen_sample_count(&model, rows - 1, 1);
        EXPECT(count == -1 || count == rows, "edge of LONG_MAX: %ld", count);
    }
    end();
}

static void test_basic_calls(void)
{
    const double p[1] = {PENDULUM_STIFFNESS};
    double phi[1] = {0.4}, phidot[1] = {-0.3}, x[2], xw[2], out_phi, out_omega, energy, error;
    double tau, v[4];
    begin("basic_calls");
    use(full_variant());
    STATUS(chaingen_initial_state(&model, phi, phidot, p, 1, x, &ws), CHAINGEN_OK);
    EXPECT(x[0] == 0.4 && x[1] == -0.3, "initial_state x = (%g, %g)", x[0], x[1]);
    xw[0] = 0.4 + 3.0 * 6.283185307179586;
    xw[1] = 2.0;
    STATUS(chaingen_outputs(&model, xw, p, 1, &out_phi, &out_omega, &energy, &error, &ws),
           CHAINGEN_OK);
    EXPECT(close_to(out_phi, 0.4, 1e-12) && out_omega == 2.0, "outputs (%g, %g)", out_phi,
           out_omega);
    EXPECT(close_to(energy, pendulum_energy(xw, PENDULUM_STIFFNESS), 1e-12), "outputs H");
    EXPECT(fabs(error) < 1e-14, "constraint error %g", error);
    STATUS(chaingen_outputs(&model, xw, p, 1, NULL, NULL, NULL, NULL, &ws), CHAINGEN_OK);
    STATUS(chaingen_holding_torques(&model, phi, p, 1, &tau, &ws), CHAINGEN_OK);
    pendulum_potential(0.4, PENDULUM_STIFFNESS, v);
    EXPECT(close_to(tau, v[1], 1e-14), "holding torque %g, V' %g", tau, v[1]);
    {
        /* The residual and its Jacobian against differences of the residual. */
        const double z[2] = {0.01, -0.02}, u[1] = {0.5};
        double f[2], g[2], jacobian[4], plus[2], minus[2], zp[2];
        int i, j;
        STATUS(chaingen_residual(&model, z, x, u, 1, p, 1, 0.05, f, &ws), CHAINGEN_OK);
        STATUS(chaingen_residual_jacobian(&model, z, x, u, 1, p, 1, 0.05, g, jacobian, &ws),
               CHAINGEN_OK);
        EXPECT(f[0] == g[0] && f[1] == g[1], "residual and residual_jacobian's F differ");
        for (j = 0; j < 2; ++j) {
            const double h = 1e-6;
            memcpy(zp, z, sizeof zp);
            zp[j] = z[j] + h;
            chaingen_residual(&model, zp, x, u, 1, p, 1, 0.05, plus, &ws);
            zp[j] = z[j] - h;
            chaingen_residual(&model, zp, x, u, 1, p, 1, 0.05, minus, &ws);
            for (i = 0; i < 2; ++i) {
                const double difference = (plus[i] - minus[i]) / (2.0 * h);
                EXPECT(close_to(jacobian[i + 2 * j], difference, 1e-7),
                       "dF%d/dz%d %.12g, difference %.12g", i, j, jacobian[i + 2 * j],
                       difference);
            }
        }
    }
    {
        double x1[2], flows[2];
        int iterations = -1;
        const double u[1] = {0.5};
        STATUS(chaingen_step(&model, x, u, 1, p, 1, 0.01, x1, flows, NULL, &ws, &iterations),
               CHAINGEN_OK);
        EXPECT(iterations > 0 && iterations <= 20, "iterations %d", iterations);
        STATUS(chaingen_step(&model, x, u, 1, p, 1, 0.01, x1, NULL, NULL, &ws, NULL),
               CHAINGEN_OK);
    }
    end();
}

/* ---- Statuses -------------------------------------------------------------------------------- */

static void test_bad_argument(void)
{
    const double p[1] = {PENDULUM_STIFFNESS}, u[1] = {0.0}, x0[2] = {0.5, 0.0};
    const double bad_x[2] = {NAN, 0.0}, inf_phi[1] = {INFINITY}, phi[1] = {0.5};
    double x1[2], samples[64], ds[4], du[2], dp[2], f[2], jacobian[4], tau;
    chaingen_options options;
    chaingen_workspace nothing;
    chaingen_stats stats;
    int iterations;
    begin("status_bad_argument");
    use(full_variant());
    memset(&nothing, 0, sizeof nothing);
    /* step */
    STATUS(chaingen_step(&model, x0, u, 1, p, 1, 0.01, NULL, NULL, NULL, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_step(&model, NULL, u, 1, p, 1, 0.01, x1, NULL, NULL, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_step(&model, x0, u, 1, p, 1, 0.0, x1, NULL, NULL, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_step(&model, x0, u, 1, p, 1, -0.01, x1, NULL, NULL, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_step(&model, x0, u, 1, p, 1, NAN, x1, NULL, NULL, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_step(&model, x0, u, 1, p, 1, INFINITY, x1, NULL, NULL, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_step(&model, x0, NULL, 1, p, 1, 0.01, x1, NULL, NULL, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_step(&model, x0, u, 0, p, 1, 0.01, x1, NULL, NULL, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_step(&model, x0, u, 2, p, 1, 0.01, x1, NULL, NULL, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_step(&model, x0, u, 1, NULL, 1, 0.01, x1, NULL, NULL, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_step(&model, x0, u, 1, p, 0, 0.01, x1, NULL, NULL, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_step(&model, x0, u, 1, p, 1, 0.01, x1, NULL, NULL, NULL, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_step(&model, x0, u, 1, p, 1, 0.01, x1, NULL, NULL, &nothing, NULL),
           CHAINGEN_BAD_ARGUMENT);
    chaingen_default_options(&model, &options);
    options.reuse_jacobian = CHAINGEN_JACOBIAN_CHORD_ACROSS_STEPS + 1;
    STATUS(chaingen_step(&model, x0, u, 1, p, 1, 0.01, x1, NULL, &options, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    options.reuse_jacobian = -1;
    STATUS(chaingen_step(&model, x0, u, 1, p, 1, 0.01, x1, NULL, &options, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    chaingen_default_options(&model, &options);
    options.energy_tol = -1.0;
    STATUS(chaingen_step(&model, x0, u, 1, p, 1, 0.01, x1, NULL, &options, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    options.energy_tol = NAN;
    STATUS(chaingen_step(&model, x0, u, 1, p, 1, 0.01, x1, NULL, &options, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    /* initial_state, outputs, holding_torques, residual */
    STATUS(chaingen_initial_state(&model, inf_phi, phi, p, 1, x1, &ws), CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_initial_state(&model, phi, inf_phi, p, 1, x1, &ws), CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_initial_state(&model, NULL, phi, p, 1, x1, &ws), CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_initial_state(&model, phi, phi, p, 1, NULL, &ws), CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_initial_state(&model, phi, phi, p, 0, x1, &ws), CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_outputs(&model, bad_x, p, 1, NULL, NULL, NULL, NULL, &ws),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_outputs(&model, NULL, p, 1, NULL, NULL, NULL, NULL, &ws),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_outputs(&model, x0, p, 1, NULL, NULL, NULL, NULL, &nothing),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_holding_torques(&model, inf_phi, p, 1, &tau, &ws), CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_holding_torques(&model, phi, p, 1, NULL, &ws), CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_residual(&model, x0, x0, u, 1, p, 1, 0.0, f, &ws), CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_residual(&model, x0, x0, u, 1, p, 1, 0.01, NULL, &ws),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_residual(&model, x0, x0, u, 0, p, 1, 0.01, f, &ws), CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_residual_jacobian(&model, x0, x0, u, 1, p, 1, -1.0, f, jacobian, &ws),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_residual_jacobian(&model, x0, x0, u, 1, p, 1, 0.01, f, NULL, &ws),
           CHAINGEN_BAD_ARGUMENT);
    /* step_sensitivities */
    STATUS(chaingen_step_sensitivities(&model, x0, u, 1, p, 1, 0.0, x1, ds, du, dp, NULL, &ws,
                                       &iterations), CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_step_sensitivities(&model, x0, NULL, 1, p, 1, 0.01, x1, ds, du, dp, NULL,
                                       &ws, &iterations), CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_step_sensitivities(&model, x0, u, 1, p, 1, 0.01, x1, NULL, du, dp, NULL,
                                       &ws, &iterations), CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_step_sensitivities(&model, x0, u, 1, p, 1, 0.01, x1, ds, NULL, dp, NULL,
                                       &ws, &iterations), CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_step_sensitivities(&model, x0, u, 1, p, 1, 0.01, x1, ds, du, NULL, NULL,
                                       &ws, &iterations), CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_step_sensitivities(&model, x0, u, 1, p, 1, 0.01, NULL, ds, du, dp, NULL,
                                       &ws, &iterations), CHAINGEN_BAD_ARGUMENT);
    /* simulate */
    STATUS(chaingen_simulate_observed(&model, x0, 0.0, 0.01, -1, 1, NULL, 1, p, 1, NULL, &ws,
                                      samples, NULL, &stats, NULL, NULL, 1, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_simulate_observed(&model, x0, 0.0, 0.01, 5, 0, NULL, 1, p, 1, NULL, &ws,
                                      samples, NULL, &stats, NULL, NULL, 1, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_simulate_observed(&model, x0, 0.0, 0.01, 5, 1, NULL, 1, p, 1, NULL, &ws,
                                      samples, NULL, &stats, NULL, NULL, 0, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_simulate_observed(&model, x0, 0.0, 0.0, 5, 1, NULL, 1, p, 1, NULL, &ws,
                                      samples, NULL, &stats, NULL, NULL, 1, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_simulate_observed(&model, x0, NAN, 0.01, 5, 1, NULL, 1, p, 1, NULL, &ws,
                                      samples, NULL, &stats, NULL, NULL, 1, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_simulate_observed(&model, x0, 0.0, 0.01, LONG_MAX, 1, NULL, 1, p, 1, NULL,
                                      &ws, samples, NULL, &stats, NULL, NULL, 1, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_simulate_observed(&model, x0, 0.0, 0.01, 5, 1, NULL, 1, p, 1, NULL, &ws,
                                      NULL, NULL, &stats, NULL, NULL, 1, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_simulate_observed(&model, NULL, 0.0, 0.01, 5, 1, NULL, 1, p, 1, NULL, &ws,
                                      samples, NULL, &stats, NULL, NULL, 1, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_simulate_observed(&model, x0, 0.0, 0.01, 5, 1, NULL, 0, p, 1, NULL, &ws,
                                      samples, NULL, &stats, NULL, NULL, 1, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_simulate_observed(&model, x0, 0.0, 0.01, 5, 1, NULL, 1, p, 1, NULL,
                                      &nothing, samples, NULL, &stats, NULL, NULL, 1, NULL),
           CHAINGEN_BAD_ARGUMENT);
    chaingen_default_options(&model, &options);
    options.rtol = 1e-20;
    STATUS(chaingen_simulate_observed(&model, x0, 0.0, 0.01, 5, 1, NULL, 1, p, 1, &options, &ws,
                                      samples, NULL, &stats, NULL, NULL, 1, NULL),
           CHAINGEN_BAD_ARGUMENT);
    options.rtol = NAN;
    STATUS(chaingen_simulate_observed(&model, x0, 0.0, 0.01, 5, 1, NULL, 1, p, 1, &options, &ws,
                                      samples, NULL, &stats, NULL, NULL, 1, NULL),
           CHAINGEN_BAD_ARGUMENT);
    options.rtol = 0.0;
    options.atol = -1e-6;
    STATUS(chaingen_simulate_observed(&model, x0, 0.0, 0.01, 5, 1, NULL, 1, p, 1, &options, &ws,
                                      samples, NULL, &stats, NULL, NULL, 1, NULL),
           CHAINGEN_BAD_ARGUMENT);
    options.atol = INFINITY;
    STATUS(chaingen_simulate_observed(&model, x0, 0.0, 0.01, 5, 1, NULL, 1, p, 1, &options, &ws,
                                      samples, NULL, &stats, NULL, NULL, 1, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_simulate_controlled(&model, x0, 0.0, 0.01, 5, 1, NULL, NULL, 1, p, 1, NULL,
                                        &ws, samples, NULL, NULL, &stats, NULL),
           CHAINGEN_BAD_ARGUMENT);
    /* the bare model: u and p NULL with nu = np = 0, and sizes that are not its own */
    use(bare_variant());
    STATUS(chaingen_step(&model, x0, NULL, 0, NULL, 0, 0.01, x1, NULL, NULL, &ws, NULL),
           CHAINGEN_OK);
    STATUS(chaingen_step(&model, x0, u, 1, NULL, 0, 0.01, x1, NULL, NULL, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_step(&model, x0, NULL, 0, p, 1, 0.01, x1, NULL, NULL, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_step(&model, x0, NULL, -1, NULL, 0, 0.01, x1, NULL, NULL, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    end();
}

static void test_bad_parameter(void)
{
    const double x0[2] = {0.5, 0.0}, u[1] = {0.0}, phi[1] = {0.5};
    double bad[1], good[1], x1[2], samples[64], tau, f[2];
    chaingen_stats stats;
    int i;
    static const double values[4] = {0.0, -1.0, NAN, INFINITY};
    begin("status_bad_parameter");
    use(full_variant());
    for (i = 0; i < 4; ++i) {
        bad[0] = values[i];
        STATUS(chaingen_step(&model, x0, u, 1, bad, 1, 0.01, x1, NULL, NULL, &ws, NULL),
               CHAINGEN_BAD_PARAMETER);
        STATUS(chaingen_initial_state(&model, phi, phi, bad, 1, x1, &ws),
               CHAINGEN_BAD_PARAMETER);
        STATUS(chaingen_outputs(&model, x0, bad, 1, NULL, NULL, NULL, NULL, &ws),
               CHAINGEN_BAD_PARAMETER);
        STATUS(chaingen_holding_torques(&model, phi, bad, 1, &tau, &ws), CHAINGEN_BAD_PARAMETER);
        STATUS(chaingen_residual(&model, x0, x0, u, 1, bad, 1, 0.01, f, &ws),
               CHAINGEN_BAD_PARAMETER);
        STATUS(chaingen_simulate_observed(&model, x0, 0.0, 0.01, 5, 1, NULL, 1, bad, 1, NULL,
                                          &ws, samples, NULL, &stats, NULL, NULL, 1, NULL),
               CHAINGEN_BAD_PARAMETER);
    }
    good[0] = 1e-300;   /* above the exclusive bound 0 */
    STATUS(chaingen_outputs(&model, x0, good, 1, NULL, NULL, NULL, NULL, &ws), CHAINGEN_OK);
    /* A bad p after a good one changes nothing: the good one's q stays in use. */
    good[0] = 7.0;
    STATUS(chaingen_holding_torques(&model, phi, good, 1, &tau, &ws), CHAINGEN_OK);
    bad[0] = 0.0;
    STATUS(chaingen_holding_torques(&model, phi, bad, 1, &tau, &ws), CHAINGEN_BAD_PARAMETER);
    {
        double again, v[4];
        STATUS(chaingen_holding_torques(&model, phi, good, 1, &again, &ws), CHAINGEN_OK);
        pendulum_potential(0.5, 7.0, v);
        EXPECT(close_to(again, v[1], 1e-14), "holding torque at k = 7: %g, V' %g", again, v[1]);
    }
    end();
}

/* q = Q(p) is derived when p changes only, and a new p ends the Newton history. */
static void test_derived_parameters(void)
{
    const double x0[2] = {0.5, 0.0}, u[1] = {0.0}, p1[1] = {5.0}, p2[1] = {6.0};
    double x1[2], x2[2];
    begin("derived_parameters");
    use(full_variant());
    STATUS(chaingen_step(&model, x0, u, 1, p1, 1, 0.01, x1, NULL, NULL, &ws, NULL), CHAINGEN_OK);
    STATUS(chaingen_step(&model, x1, u, 1, p1, 1, 0.01, x2, NULL, NULL, &ws, NULL), CHAINGEN_OK);
    EXPECT(pendulum_knob.calls[PENDULUM_F_PARAMETERS] == 1, "parameters evaluated %ld times",
           pendulum_knob.calls[PENDULUM_F_PARAMETERS]);
    EXPECT(store->scalars.history >= 1, "no history after two chained steps");
    STATUS(chaingen_step(&model, x2, u, 1, p2, 1, 0.01, x1, NULL, NULL, &ws, NULL), CHAINGEN_OK);
    EXPECT(pendulum_knob.calls[PENDULUM_F_PARAMETERS] == 2, "parameters evaluated %ld times",
           pendulum_knob.calls[PENDULUM_F_PARAMETERS]);
    EXPECT(store->scalars.q_valid == 1, "q not valid");
    end();
}

static void test_evaluation_failed(void)
{
    static const int step_functions[6] = {PENDULUM_F_PARAMETERS, PENDULUM_F_RESIDUAL_JACOBIAN,
                                          PENDULUM_F_PREDICTOR, PENDULUM_F_NEXT_STATE,
                                          PENDULUM_F_SEGMENT_MARGINS, PENDULUM_F_ENERGY_TERMS};
    const double p[1] = {PENDULUM_STIFFNESS}, u[1] = {0.2}, x0[2] = {0.5, 0.3}, phi[1] = {0.5};
    double x1[2], untouched[2] = {-7.0, -7.0}, tau, samples[64], ds[4], du[2], dp[2];
    chaingen_options options;
    chaingen_stats stats;
    int i, iterations;
    begin("status_evaluation_failed");
    for (i = 0; i < 6; ++i) {
        use(full_variant());
        pendulum_knob.fail_mask = 1u << step_functions[i];
        memcpy(x1, untouched, sizeof x1);
        STATUS(chaingen_step(&model, x0, u, 1, p, 1, 0.01, x1, NULL, NULL, &ws, NULL),
               CHAINGEN_EVALUATION_FAILED);
        EXPECT(x1[0] == -7.0 && x1[1] == -7.0, "x1 written by a failed step (function %d)",
               step_functions[i]);
    }
    use(full_variant());
    pendulum_knob.fail_mask = 1u << PENDULUM_F_INITIAL_STATE;
    STATUS(chaingen_initial_state(&model, phi, phi, p, 1, x1, &ws), CHAINGEN_EVALUATION_FAILED);
    pendulum_knob.fail_mask = 1u << PENDULUM_F_OUTPUTS;
    STATUS(chaingen_outputs(&model, x0, p, 1, NULL, NULL, NULL, NULL, &ws),
           CHAINGEN_EVALUATION_FAILED);
    STATUS(chaingen_simulate_observed(&model, x0, 0.0, 0.01, 5, 1, NULL, 1, p, 1, NULL, &ws,
                                      samples, NULL, &stats, NULL, NULL, 1, NULL),
           CHAINGEN_EVALUATION_FAILED);
    pendulum_knob.fail_mask = 1u << PENDULUM_F_HOLDING_TORQUES;
    STATUS(chaingen_holding_torques(&model, phi, p, 1, &tau, &ws), CHAINGEN_EVALUATION_FAILED);
    pendulum_knob.fail_mask = 1u << PENDULUM_F_SENSITIVITY_RHS;
    STATUS(chaingen_step_sensitivities(&model, x0, u, 1, p, 1, 0.01, x1, ds, du, dp, NULL, &ws,
                                       &iterations), CHAINGEN_EVALUATION_FAILED);
    pendulum_knob.fail_mask = 1u << PENDULUM_F_SENSITIVITY_MAP;
    STATUS(chaingen_step_sensitivities(&model, x0, u, 1, p, 1, 0.01, x1, ds, du, dp, NULL, &ws,
                                       &iterations), CHAINGEN_EVALUATION_FAILED);
    /* A failed evaluation is not climbed out of: no split, no fallback. */
    pendulum_knob.fail_mask = 1u << PENDULUM_F_NEXT_STATE;
    STATUS(step(x0, 0.2, 0.01, x1, NULL, NULL, NULL), CHAINGEN_EVALUATION_FAILED);
    EXPECT(store->scalars.step_splits == 0, "a failed evaluation split the step");
    /* residual() alone fails: full Newton never calls it; Newton-chord's second iterate does,
     * and its failure is final (the ladder does not climb past a failed evaluation). */
    pendulum_knob.fail_mask = 1u << PENDULUM_F_RESIDUAL;
    chaingen_workspace_init(&model, &ws);
    STATUS(step(x0, 0.2, 0.01, x1, NULL, NULL, NULL), CHAINGEN_OK);
    chaingen_default_options(&model, &options);
    options.reuse_jacobian = CHAINGEN_JACOBIAN_PER_STEP;
    chaingen_workspace_init(&model, &ws);
    STATUS(step(x0, 0.2, 0.01, x1, NULL, &options, NULL), CHAINGEN_EVALUATION_FAILED);
    EXPECT(store->scalars.step_fallbacks == 0, "a failed evaluation fell back to full Newton");
    /* joint_maps of a composed step chained in x */
    {
        pendulum_variant v = full_variant();
        v.composition = PENDULUM_YOSHIDA4;
        v.chain_state = 1;
        use(v);
        pendulum_knob.fail_mask = 1u << PENDULUM_F_JOINT_MAPS;
        STATUS(chaingen_step_sensitivities(&model, x0, u, 1, p, 1, 0.01, x1, ds, du, dp, NULL,
                                           &ws, &iterations), CHAINGEN_EVALUATION_FAILED);
    }
    end();
}

static void test_nonfinite(void)
{
    const double x0[2] = {0.5, 0.3};
    double x1[2] = {-7.0, -7.0};
    int iterations = 0;
    begin("status_nonfinite");
    use(full_variant());
    pendulum_knob.nan_residual = 1;
    STATUS(step(x0, 0.2, 0.01, x1, NULL, NULL, &iterations), CHAINGEN_NONFINITE);
    EXPECT(x1[0] == -7.0 && x1[1] == -7.0, "x1 written by a failed step");
    EXPECT(store->scalars.step_splits == CHAINGEN_MAX_SPLIT, "splits %ld, expected %d",
           store->scalars.step_splits, CHAINGEN_MAX_SPLIT);
    /* A non-finite new state (next_state's NaN), beyond Newton. */
    use(full_variant());
    pendulum_knob.state_kick = NAN;
    STATUS(step(x0, 0.2, 0.01, x1, NULL, NULL, &iterations), CHAINGEN_NONFINITE);
    EXPECT(x1[0] == -7.0 && x1[1] == -7.0, "x1 written by a failed step");
    end();
}

static void test_singular(void)
{
    const double x0[2] = {0.5, 0.3};
    double x1[2];
    const double p[1] = {PENDULUM_STIFFNESS}, u[1] = {0.0};
    double ds[4], du[2], dp[2];
    int iterations;
    begin("status_singular_jacobian");
    use(full_variant());
    pendulum_knob.zero_jacobian = 1;
    STATUS(step(x0, 0.0, 0.01, x1, NULL, NULL, NULL), CHAINGEN_SINGULAR_JACOBIAN);
    STATUS(chaingen_step_sensitivities(&model, x0, u, 1, p, 1, 0.01, x1, ds, du, dp, NULL, &ws,
                                       &iterations), CHAINGEN_SINGULAR_JACOBIAN);
    end();
}

static void test_not_converged(void)
{
    const double x0[2] = {0.5, 0.3};
    double x1[2], x2[2];
    chaingen_options options;
    int iterations = 0;
    begin("status_not_converged");
    use(full_variant());
    pendulum_knob.jacobian_scale = 1.0 / 1.9;   /* Newton contracts by 0.9 an iterate */
    STATUS(step(x0, 0.0, 0.01, x1, NULL, NULL, &iterations), CHAINGEN_NOT_CONVERGED);
    /* One iteration a solve: the whole step, then its first halves down to MAX_SPLIT (the second
     * half of a failed first half is never tried). */
    use(full_variant());
    chaingen_default_options(&model, &options);
    options.max_iterations = 1;
    iterations = 0;
    STATUS(step(x0, 0.0, 0.01, x1, NULL, &options, &iterations), CHAINGEN_NOT_CONVERGED);
    EXPECT(iterations == CHAINGEN_MAX_SPLIT + 1, "iterations %d, expected %d", iterations,
           CHAINGEN_MAX_SPLIT + 1);
    EXPECT(store->scalars.step_splits == CHAINGEN_MAX_SPLIT, "splits %ld",
           store->scalars.step_splits);
    /* A chained (warm) step that fails is retried once from the predictor: one more solve. */
    use(full_variant());
    STATUS(step(x0, 0.0, 0.01, x1, NULL, NULL, NULL), CHAINGEN_OK);
    iterations = 0;
    STATUS(step(x1, 0.0, 0.01, x2, NULL, &options, &iterations), CHAINGEN_NOT_CONVERGED);
    EXPECT(iterations == CHAINGEN_MAX_SPLIT + 2, "chained: iterations %d, expected %d",
           iterations, CHAINGEN_MAX_SPLIT + 2);
    /* The kept Jacobian's rung: Newton-chord, then full Newton, each one solve. */
    use(full_variant());
    options.reuse_jacobian = CHAINGEN_JACOBIAN_PER_STEP;
    iterations = 0;
    STATUS(step(x0, 0.0, 0.01, x1, NULL, &options, &iterations), CHAINGEN_NOT_CONVERGED);
    EXPECT(iterations == 2 * (CHAINGEN_MAX_SPLIT + 1), "chord: iterations %d, expected %d",
           iterations, 2 * (CHAINGEN_MAX_SPLIT + 1));
    end();
}

/* A step past a fold of its root has none (the knob: F1^2 + fold for steps longer than 0.006 s).
 * A package whose own Newton is simplified (vi's), run with it, stops at the first Newton step
 * that fails the monotonicity test (the next update, by the Jacobian evaluated at its start,
 * did not shrink) and skips full Newton's rung: the step is split after a few solves, and its
 * halves, which have a root, pass. Every other configuration keeps its failure path, every rung
 * run to max_iterations: full Newton, Newton-chord, and simplified Newton in a package whose
 * own Newton is another (es, midpoint; the pendulum's is full Newton). */
static void test_diverged(void)
{
    const double x0[2] = {0.5, 0.3};
    double x1[2], reference[2];
    chaingen_options options;
    int own, mode, iterations[2][3];
    begin("diverged");
    use(full_variant());
    chaingen_default_options(&model, &options);
    options.warm_start = 0;
    options.energy_tol = 0.0;
    STATUS(step(x0, 0.0, 0.005, reference, NULL, &options, NULL), CHAINGEN_OK);
    STATUS(step(reference, 0.0, 0.005, reference, NULL, &options, NULL), CHAINGEN_OK);
    for (own = 0; own < 2; ++own) {
        for (mode = 0; mode < 3; ++mode) {
            use(full_variant());
            if (own) {
                model.defaults.reuse_jacobian = CHAINGEN_JACOBIAN_ACROSS_STEPS;
            }
            pendulum_knob.fold = 1e-3;
            pendulum_knob.above_dt = 0.006;
            options.reuse_jacobian = mode;
            iterations[own][mode] = 0;
            STATUS(step(x0, 0.0, 0.01, x1, NULL, &options, &iterations[own][mode]),
                   CHAINGEN_OK);
            EXPECT(store->scalars.step_splits == 1 && store->scalars.step_fallbacks == 0,
                   "own %d, mode %d: %ld splits, %ld fallbacks", own, mode,
                   store->scalars.step_splits, store->scalars.step_fallbacks);
            EXPECT(close_to(x1[0], reference[0], 1e-9) && close_to(x1[1], reference[1], 1e-9),
                   "own %d, mode %d: the halves end at (%.15g, %.15g), not at (%.15g, %.15g)",
                   own, mode, x1[0], x1[1], reference[0], reference[1]);
        }
        printf("# diverged, own Newton %s: iterations full %d, simplified %d, chord %d\n",
               own ? "simplified" : "full", iterations[own][0], iterations[own][1],
               iterations[own][2]);
    }
    EXPECT(iterations[1][CHAINGEN_JACOBIAN_ACROSS_STEPS] < 15,
           "simplified, its own Newton: %d iterations for a step without a root and its halves",
           iterations[1][CHAINGEN_JACOBIAN_ACROSS_STEPS]);
    for (own = 0; own < 2; ++own) {
        EXPECT(iterations[own][CHAINGEN_JACOBIAN_EVERY_ITERATE] > options.max_iterations
                   && iterations[own][CHAINGEN_JACOBIAN_PER_STEP] > 2 * options.max_iterations,
               "own %d: full Newton %d, chord %d iterations: a rung gave up early", own,
               iterations[own][CHAINGEN_JACOBIAN_EVERY_ITERATE],
               iterations[own][CHAINGEN_JACOBIAN_PER_STEP]);
    }
    EXPECT(iterations[0][CHAINGEN_JACOBIAN_ACROSS_STEPS] > 2 * options.max_iterations,
           "simplified in a package of another Newton: %d iterations: a rung gave up early",
           iterations[0][CHAINGEN_JACOBIAN_ACROSS_STEPS]);
    end();
}

static void test_segment_collapsed(void)
{
    pendulum_variant v = full_variant();
    const double p[1] = {PENDULUM_STIFFNESS}, u[1] = {0.0};
    double phi[1] = {PENDULUM_COLLAPSE_ANGLE}, rest[1] = {0.0}, x[2], tau, x1[2] = {-7.0, -7.0};
    double samples[64], ds[4], du[2], dp[2];
    chaingen_stats stats;
    int iterations;
    begin("status_segment_collapsed");
    v.collapse = 1;
    use(v);
    STATUS(chaingen_initial_state(&model, phi, rest, p, 1, x, &ws), CHAINGEN_SEGMENT_COLLAPSED);
    STATUS(chaingen_holding_torques(&model, phi, p, 1, &tau, &ws), CHAINGEN_SEGMENT_COLLAPSED);
    x[0] = PENDULUM_COLLAPSE_ANGLE;
    x[1] = 0.0;
    STATUS(step(x, 0.0, 0.01, x1, NULL, NULL, NULL), CHAINGEN_SEGMENT_COLLAPSED);
    STATUS(chaingen_step_sensitivities(&model, x, u, 1, p, 1, 0.01, x1, ds, du, dp, NULL, &ws,
                                       &iterations), CHAINGEN_SEGMENT_COLLAPSED);
    /* The outputs of such a state are defined (its segment's length only). */
    STATUS(chaingen_outputs(&model, x, p, 1, NULL, NULL, NULL, NULL, &ws), CHAINGEN_OK);
    /* A run from it: row 0, then no step. */
    memset(&stats, 0xff, sizeof stats);
    STATUS(chaingen_simulate_observed(&model, x, 0.5, 0.01, 5, 1, NULL, 1, p, 1, NULL, &ws,
                                      samples, NULL, &stats, NULL, NULL, 1, NULL),
           CHAINGEN_SEGMENT_COLLAPSED);
    EXPECT(stats.steps == 0 && samples[0] == 0.5, "run from a collapsed start: %ld steps",
           stats.steps);
    /* Just off the anchor it starts (1e-3 of the geometry is far above the reader's limit). */
    phi[0] = PENDULUM_COLLAPSE_ANGLE + 1e-3;
    STATUS(chaingen_initial_state(&model, phi, rest, p, 1, x, &ws), CHAINGEN_OK);
    /* A step through the anchor: the segment turns by 180 degrees, in every half too. */
    x[0] = PENDULUM_COLLAPSE_ANGLE - 0.2;
    x[1] = 4.0;
    x1[0] = x1[1] = -7.0;
    STATUS(step(x, 0.0, 0.1, x1, NULL, NULL, NULL), CHAINGEN_SEGMENT_COLLAPSED);
    EXPECT(x1[0] == -7.0, "x1 written by a failed step");
    end();
}

typedef struct {
    long calls;
    long stop_at;         /* return nonzero at this many steps */
    long last;
    chaingen_control *control;   /* set control->stop at stop_at instead */
} observation;

static int observe(long steps, void *context)
{
    observation *o = (observation *)context;
    ++o->calls;
    o->last = steps;
    if (steps == o->stop_at) {
        if (o->control) {
            o->control->stop = 1;
            return 0;
        }
        return 1;
    }
    return 0;
}

typedef struct {
    long calls;
    long stop_at;
    long steps[64];
    double times[64], phi[64], omega[64];
    double gain;
} controlling;

static int control_law(long k, double t, const double *phi, const double *omega, double *u,
                       void *context)
{
    controlling *c = (controlling *)context;
    if (c->calls < 64) {
        c->steps[c->calls] = k;
        c->times[c->calls] = t;
        c->phi[c->calls] = phi[0];
        c->omega[c->calls] = omega[0];
    }
    ++c->calls;
    if (k == c->stop_at) {
        return 1;
    }
    u[0] = -c->gain * phi[0] + 0.1 * (double)c->calls;
    return 0;
}

static void test_interrupted(void)
{
    const double p[1] = {PENDULUM_STIFFNESS}, x0[2] = {0.5, 0.0};
    double samples[7 * 32];
    chaingen_stats stats;
    chaingen_control control;
    observation o;
    controlling c;
    begin("status_interrupted");
    use(full_variant());
    memset(&o, 0, sizeof o);
    o.stop_at = 6;
    STATUS(chaingen_simulate_observed(&model, x0, 0.0, 0.01, 20, 1, NULL, 1, p, 1, NULL, &ws,
                                      samples, NULL, &stats, observe, &o, 2, NULL),
           CHAINGEN_INTERRUPTED);
    EXPECT(stats.steps == 6 && o.calls == 3 && o.last == 6,
           "observer stop: %ld steps, %ld calls", stats.steps, o.calls);
    /* control->stop before the run: no step */
    memset(&control, 0, sizeof control);
    control.stop = 1;
    STATUS(chaingen_simulate_observed(&model, x0, 0.0, 0.01, 20, 1, NULL, 1, p, 1, NULL, &ws,
                                      samples, NULL, &stats, NULL, NULL, 1, &control),
           CHAINGEN_INTERRUPTED);
    EXPECT(stats.steps == 0, "stopped before the run: %ld steps", stats.steps);
    /* control->stop set during the run (here by the observer) */
    memset(&control, 0, sizeof control);
    memset(&o, 0, sizeof o);
    o.stop_at = 4;
    o.control = &control;
    STATUS(chaingen_simulate_observed(&model, x0, 0.0, 0.01, 20, 1, NULL, 1, p, 1, NULL, &ws,
                                      samples, NULL, &stats, observe, &o, 1, &control),
           CHAINGEN_INTERRUPTED);
    EXPECT(stats.steps == 4 && control.steps == 4, "control stop: %ld steps, control %ld",
           stats.steps, control.steps);
    /* the controller asks to stop before step 6 */
    memset(&c, 0, sizeof c);
    c.stop_at = 6;
    STATUS(chaingen_simulate_controlled(&model, x0, 0.0, 0.01, 20, 1, control_law, &c, 2, p, 1,
                                        NULL, &ws, samples, NULL, NULL, &stats, NULL),
           CHAINGEN_INTERRUPTED);
    EXPECT(stats.steps == 6 && c.calls == 4, "controller stop: %ld steps, %ld calls",
           stats.steps, c.calls);
    end();
}

static void test_step_too_small(void)
{
    pendulum_variant v = full_variant();
    const double x0[2] = {0.5, 0.0};
    double samples[7 * 8], x_final[2];
    chaingen_options options;
    chaingen_stats stats;
    begin("status_step_too_small");
    v.energy_check = 0;   /* the kick breaks the energy balance too: keep the error test's */
    use(v);
    pendulum_knob.state_kick = 1e-3;   /* a step error that no step length removes */
    chaingen_default_options(&model, &options);
    options.rtol = 1e-6;
    options.atol = 1e-6;
    STATUS(simulate(x0, 0.0, 0.1, 3, 1, NULL, &options, samples, x_final, &stats),
           CHAINGEN_STEP_TOO_SMALL);
    EXPECT(stats.steps == 0 && stats.rejected_steps > 0, "%ld steps, %ld rejected", stats.steps,
           stats.rejected_steps);
    /* Newton failing at every length: the run stops with Newton's status instead. */
    use(v);
    pendulum_knob.nan_residual = 1;
    STATUS(simulate(x0, 0.0, 0.1, 3, 1, NULL, &options, samples, x_final, &stats),
           CHAINGEN_NONFINITE);
    EXPECT(stats.steps == 0 && stats.rejected_steps > 0, "%ld steps, %ld rejected", stats.steps,
           stats.rejected_steps);
    end();
}

static void test_energy_jump(void)
{
    const double x0[2] = {0.5, 1.0};
    double x1[2] = {-7.0, -7.0};
    chaingen_options options;
    begin("status_energy_jump");
    use(full_variant());
    pendulum_knob.energy_jump = 1e4;
    STATUS(step(x0, 0.0, 0.01, x1, NULL, NULL, NULL), CHAINGEN_ENERGY_JUMP);
    EXPECT(x1[0] == -7.0, "x1 written by a failed step");
    EXPECT(store->scalars.step_splits == CHAINGEN_MAX_SPLIT, "splits %ld",
           store->scalars.step_splits);
    chaingen_default_options(&model, &options);
    options.energy_tol = 0.0;   /* no check */
    STATUS(step(x0, 0.0, 0.01, x1, NULL, &options, NULL), CHAINGEN_OK);
    /* A miss within energy_tol (T0 + T1) passes, unsplit. */
    use(full_variant());
    pendulum_knob.energy_jump = 0.3;
    STATUS(step(x0, 0.0, 0.02, x1, NULL, NULL, NULL), CHAINGEN_OK);
    EXPECT(store->scalars.step_splits == 0, "a small miss split the step");
    /* Round-off scales with the magnitude S of H's terms, not with H: a miss of 1e-6 J with
     * next to no tolerance on T fails, and passes where H's terms are 1e12 J that cancel (the
     * round-off allowance 1024 eps S is then 4.5e-4 J), as a controlled loop's H_d at rest. */
    use(full_variant());
    chaingen_default_options(&model, &options);
    options.energy_tol = 1e-300;
    pendulum_knob.energy_jump = 1e-6 / (x0[1] * 0.01);
    STATUS(step(x0, 0.0, 0.01, x1, NULL, &options, NULL), CHAINGEN_ENERGY_JUMP);
    use(full_variant());
    pendulum_knob.energy_jump = 1e-6 / (x0[1] * 0.01);
    pendulum_knob.energy_cancelled = 1e12;
    STATUS(step(x0, 0.0, 0.01, x1, NULL, &options, NULL), CHAINGEN_OK);
    EXPECT(store->scalars.step_splits == 0, "a miss within the round-off of H's terms split");
    end();
}

static void test_unavailable(void)
{
    pendulum_variant v = full_variant();
    const double p[1] = {PENDULUM_STIFFNESS}, u[1] = {0.0}, x0[2] = {0.5, 0.0}, phi[1] = {0.5};
    double x1[2], ds[4], du[2], dp[2], tau, samples[64];
    chaingen_stats stats;
    controlling c;
    int iterations;
    begin("status_unavailable");
    v.sensitivities = 0;
    v.holding = 0;
    use(v);
    STATUS(chaingen_step_sensitivities(&model, x0, u, 1, p, 1, 0.01, x1, ds, du, dp, NULL, &ws,
                                       &iterations), CHAINGEN_UNAVAILABLE);
    STATUS(chaingen_holding_torques(&model, phi, p, 1, &tau, &ws), CHAINGEN_UNAVAILABLE);
    use(bare_variant());
    memset(&c, 0, sizeof c);
    c.stop_at = -1;
    STATUS(chaingen_simulate_controlled(&model, x0, 0.0, 0.01, 5, 1, control_law, &c, 1, NULL, 0,
                                        NULL, &ws, samples, NULL, NULL, &stats, NULL),
           CHAINGEN_UNAVAILABLE);
    EXPECT(c.calls == 0, "the controller of an unactuated model was called");
    end();
}

/* ---- Newton ---------------------------------------------------------------------------------- */

static void inputs(double *u, long n, double dt)
{
    long k;
    for (k = 0; k < n; ++k) {
        u[k] = 0.8 * sin(3.0 * (double)k * dt);
    }
}

static void test_newton_modes(void)
{
    enum { STEPS = 400 };
    static double u[STEPS], samples[7 * (STEPS + 1)];
    const double x0[2] = {1.0, 0.0};
    double finals[3][2];
    long jacobians[3], residuals[3];
    chaingen_stats stats[3];
    chaingen_options options;
    int mode;
    begin("newton_modes");
    use(full_variant());
    inputs(u, STEPS, 0.01);
    for (mode = 0; mode < 3; ++mode) {
        chaingen_default_options(&model, &options);
        options.reuse_jacobian = mode;
        pendulum_knobs_reset();
        STATUS(simulate(x0, 0.0, 0.01, STEPS, 1, u, &options, samples, finals[mode],
                        &stats[mode]), CHAINGEN_OK);
        jacobians[mode] = pendulum_knob.calls[PENDULUM_F_RESIDUAL_JACOBIAN];
        residuals[mode] = pendulum_knob.calls[PENDULUM_F_RESIDUAL];
        EXPECT(stats[mode].steps == STEPS && stats[mode].full_newton_fallbacks == 0
                   && stats[mode].split_steps == 0,
               "mode %d: %ld steps, %ld fallbacks, %ld splits", mode, stats[mode].steps,
               stats[mode].full_newton_fallbacks, stats[mode].split_steps);
    }
    for (mode = 1; mode < 3; ++mode) {
        EXPECT(close_to(finals[mode][0], finals[0][0], 1e-8)
                   && close_to(finals[mode][1], finals[0][1], 1e-8),
               "mode %d ends at (%.15g, %.15g), full Newton at (%.15g, %.15g)", mode,
               finals[mode][0], finals[mode][1], finals[0][0], finals[0][1]);
    }
    EXPECT(jacobians[0] == stats[0].newton_iterations && residuals[0] == 0,
           "full Newton: %ld Jacobians, %ld residuals, %ld iterations", jacobians[0],
           residuals[0], stats[0].newton_iterations);
    EXPECT(jacobians[2] >= STEPS && jacobians[2] < stats[2].newton_iterations && residuals[2] > 0,
           "chord: %ld Jacobians, %ld residuals, %ld iterations", jacobians[2], residuals[2],
           stats[2].newton_iterations);
    EXPECT(jacobians[1] < STEPS / 4 && residuals[1] > 0,
           "simplified: %ld Jacobians over %d steps", jacobians[1], STEPS);
    {
        /* Simplified Newton keeps the run's Jacobian for a step of its dt, and evaluates one
         * anew for another dt. */
        double x1[2];
        chaingen_default_options(&model, &options);
        options.reuse_jacobian = CHAINGEN_JACOBIAN_ACROSS_STEPS;
        STATUS(simulate(x0, 0.0, 0.01, STEPS, 1, u, &options, samples, finals[1], &stats[1]),
               CHAINGEN_OK);
        pendulum_knobs_reset();
        STATUS(step(finals[1], 0.0, 0.01, x1, NULL, &options, NULL), CHAINGEN_OK);
        EXPECT(pendulum_knob.calls[PENDULUM_F_RESIDUAL_JACOBIAN] == 0,
               "simplified, same dt: %ld Jacobians",
               pendulum_knob.calls[PENDULUM_F_RESIDUAL_JACOBIAN]);
        STATUS(step(x1, 0.0, 0.02, finals[1], NULL, &options, NULL), CHAINGEN_OK);
        EXPECT(pendulum_knob.calls[PENDULUM_F_RESIDUAL_JACOBIAN] >= 1,
               "simplified, another dt: no Jacobian evaluated");
    }
    end();
}

/* Full Newton at the round-off floor: with a residual whose round-off lies above the Jacobian's
 * terms (the knob adds a pseudo-random error to F), the updates stop shrinking at a level above
 * a tight update tolerance. The floor test must see it and accept the step in a few iterations
 * (before it did, it compared each update with none, since every iterate's Jacobian is new, and
 * the step ran out of iterations and split: vi on 18 links under the check's tolerances). Once
 * with noise below CG_ROUNDOFF_RESIDUAL (the residual is round-off of its scale), once above it
 * (only the residual's stagnation tells). */
static void test_round_off_floor(void)
{
    static const double noises[2] = {1e-14, 1e-11};
    const double x0[2] = {1.0, 0.5};
    double x1[2], reference[2];
    chaingen_options options;
    int k, iterations = 0;
    begin("round_off_floor");
    use(full_variant());
    chaingen_default_options(&model, &options);
    options.reuse_jacobian = CHAINGEN_JACOBIAN_EVERY_ITERATE;
    options.warm_start = 0;
    STATUS(step(x0, 0.2, 0.01, reference, NULL, &options, &iterations), CHAINGEN_OK);
    options.update_rtol = 1e-16;
    options.update_atol = 1e-16;
    options.max_iterations = 40;
    for (k = 0; k < 2; ++k) {
        pendulum_knobs_reset();
        pendulum_knob.residual_noise = noises[k];
        iterations = 0;
        STATUS(step(x0, 0.2, 0.01, x1, NULL, &options, &iterations), CHAINGEN_OK);
        EXPECT(iterations <= 12 && store->scalars.step_splits == 0,
               "noise %g: %d iterations, %ld splits", noises[k], iterations,
               store->scalars.step_splits);
        EXPECT(close_to(x1[0], reference[0], 1e3 * noises[k])
                   && close_to(x1[1], reference[1], 1e3 * noises[k]),
               "noise %g: ends at (%.17g, %.17g), without noise (%.17g, %.17g)", noises[k],
               x1[0], x1[1], reference[0], reference[1]);
    }
    end();
}

static void test_fallback(void)
{
    enum { STEPS = 20 };
    static double samples[7 * (STEPS + 1)];
    const double x0[2] = {1.0, 0.0};
    double x1[2], reference[2], x_final[2];
    chaingen_options options;
    chaingen_stats stats;
    int mode;
    begin("full_newton_fallback");
    use(full_variant());
    STATUS(step(x0, 0.3, 0.01, reference, NULL, NULL, NULL), CHAINGEN_OK);
    for (mode = 1; mode < 3; ++mode) {
        /* residual() alone NaN: the kept Jacobian's iterates fail, full Newton passes. */
        use(full_variant());
        pendulum_knob.nan_residual = 2;
        chaingen_default_options(&model, &options);
        options.reuse_jacobian = mode;
        STATUS(step(x0, 0.3, 0.01, x1, NULL, &options, NULL), CHAINGEN_OK);
        EXPECT(store->scalars.step_fallbacks == 1 && store->scalars.step_splits == 0,
               "mode %d: %ld fallbacks, %ld splits", mode, store->scalars.step_fallbacks,
               store->scalars.step_splits);
        EXPECT(close_to(x1[0], reference[0], 1e-10) && close_to(x1[1], reference[1], 1e-10),
               "mode %d: fallback's x1 differs from full Newton's", mode);
        STATUS(simulate(x0, 0.0, 0.01, STEPS, 1, NULL, &options, samples, x_final, &stats),
               CHAINGEN_OK);
        EXPECT(stats.full_newton_fallbacks == STEPS && stats.split_steps == 0,
               "mode %d: %ld fallbacks in %d steps", mode, stats.full_newton_fallbacks, STEPS);
    }
    end();
}

static void test_warm_start(void)
{
    enum { STEPS = 300 };
    static double u[STEPS], samples[7 * (STEPS + 1)];
    const double x0[2] = {1.0, 0.5};
    double warm[2], cold[2], x[2], next[2];
    chaingen_stats warm_stats, cold_stats;
    chaingen_options options;
    long k;
    int iterations, total = 0;
    begin("warm_start");
    use(full_variant());
    inputs(u, STEPS, 0.01);
    chaingen_default_options(&model, &options);
    STATUS(simulate(x0, 0.0, 0.01, STEPS, 1, u, &options, samples, warm, &warm_stats),
           CHAINGEN_OK);
    options.warm_start = 0;
    STATUS(simulate(x0, 0.0, 0.01, STEPS, 1, u, &options, samples, cold, &cold_stats),
           CHAINGEN_OK);
    EXPECT(close_to(warm[0], cold[0], 1e-9) && close_to(warm[1], cold[1], 1e-9),
           "warm (%.15g, %.15g), cold (%.15g, %.15g)", warm[0], warm[1], cold[0], cold[1]);
    EXPECT(warm_stats.newton_iterations < cold_stats.newton_iterations,
           "warm start: %ld iterations, cold %ld", warm_stats.newton_iterations,
           cold_stats.newton_iterations);
    /* step() continues the workspace's history as simulate does. */
    chaingen_workspace_init(&model, &ws);
    memcpy(x, x0, sizeof x);
    for (k = 0; k < STEPS; ++k) {
        iterations = 0;
        STATUS(step(x, u[k], 0.01, next, NULL, NULL, &iterations), CHAINGEN_OK);
        total += iterations;
        memcpy(x, next, sizeof x);
    }
    EXPECT(x[0] == warm[0] && x[1] == warm[1] && total == warm_stats.newton_iterations,
           "stepping by step(): (%.17g, %.17g) in %d iterations, simulate (%.17g, %.17g) in %ld",
           x[0], x[1], total, warm[0], warm[1], warm_stats.newton_iterations);
    end();
}

/* A copy of the workspace is a copy of the solver's state: both continue alike. */
static void test_workspace_copy(void)
{
    const double x0[2] = {1.0, 0.5};
    double x[2], a[2], b[2];
    storage *copy;
    chaingen_workspace copied;
    chaingen_options options;
    int k;
    begin("workspace_copy");
    use(full_variant());
    chaingen_default_options(&model, &options);
    options.reuse_jacobian = CHAINGEN_JACOBIAN_ACROSS_STEPS;
    memcpy(x, x0, sizeof x);
    for (k = 0; k < 5; ++k) {
        STATUS(step(x, 0.1, 0.01, a, NULL, &options, NULL), CHAINGEN_OK);
        memcpy(x, a, sizeof x);
    }
    copy = (storage *)calloc(1, sizeof *copy);
    if (!copy || !allocate(copy)) {
        failf(__LINE__, "out of memory");
        return;
    }
    copy->scalars = store->scalars;
    memcpy(copy->ints, store->ints, sizeof(int) * (size_t)chaingen_workspace_ints(&model));
    memcpy(copy->doubles, store->doubles,
           sizeof(double) * (size_t)chaingen_workspace_doubles(&model));
    copied = view(copy);
    for (k = 0; k < 5; ++k) {
        const double u[1] = {0.1};
        STATUS(step(x, 0.1, 0.01, a, NULL, &options, NULL), CHAINGEN_OK);
        STATUS(chaingen_step(&model, x, u, 1, STIFFNESS, 1, 0.01, b, NULL, &options, &copied,
                             NULL), CHAINGEN_OK);
        EXPECT(a[0] == b[0] && a[1] == b[1], "step %d: the copy differs", k);
        memcpy(x, a, sizeof x);
    }
    free(copy->ints);
    free(copy->doubles);
    free(copy);
    end();
}

static void test_split_steps(void)
{
    enum { STEPS = 10 };
    static double samples[7 * (2 * STEPS + 1)];
    const double x0[2] = {1.0, 0.5};
    double x1[2], middle[2], halves[2], flows[2], half_flows[2][2], whole[2], split[2];
    chaingen_stats stats, fine_stats;
    int iterations = 0;
    begin("split_steps");
    use(full_variant());
    STATUS(step(x0, 0.4, 0.01, middle, half_flows[0], NULL, NULL), CHAINGEN_OK);
    STATUS(step(middle, 0.4, 0.01, halves, half_flows[1], NULL, NULL), CHAINGEN_OK);
    /* Newton crawls on steps longer than 0.015 s: the whole step fails, its halves pass. */
    use(full_variant());
    pendulum_knob.jacobian_scale = 1.0 / 1.9;
    pendulum_knob.above_dt = 0.015;
    STATUS(step(x0, 0.4, 0.02, x1, flows, NULL, &iterations), CHAINGEN_OK);
    EXPECT(store->scalars.step_splits == 1, "%ld splits", store->scalars.step_splits);
    EXPECT(iterations > 20, "iterations %d: the failed whole step's are counted", iterations);
    EXPECT(close_to(x1[0], halves[0], 1e-10) && close_to(x1[1], halves[1], 1e-10),
           "split step (%.15g, %.15g), two half steps (%.15g, %.15g)", x1[0], x1[1], halves[0],
           halves[1]);
    EXPECT(close_to(flows[0], half_flows[0][0] + half_flows[1][0], 1e-12)
               && close_to(flows[1], half_flows[0][1] + half_flows[1][1], 1e-12),
           "split step's flows are not the halves' sum");
    STATUS(simulate(x0, 0.0, 0.02, STEPS, 1, NULL, NULL, samples, split, &stats), CHAINGEN_OK);
    EXPECT(stats.split_steps == STEPS && stats.steps == STEPS && stats.accepted_steps == STEPS,
           "%ld split steps of %ld", stats.split_steps, stats.steps);
    EXPECT(stats.newton_iterations >= STEPS * 20 && stats.max_newton_iterations > 20,
           "iterations %ld (max %d)", stats.newton_iterations, stats.max_newton_iterations);
    use(full_variant());
    STATUS(simulate(x0, 0.0, 0.01, 2 * STEPS, 1, NULL, NULL, samples, whole, &fine_stats),
           CHAINGEN_OK);
    EXPECT(close_to(split[0], whole[0], 1e-9) && close_to(split[1], whole[1], 1e-9),
           "split run (%.15g, %.15g), run at dt/2 (%.15g, %.15g)", split[0], split[1], whole[0],
           whole[1]);
    end();
}

/* ---- Energy ---------------------------------------------------------------------------------- */

static void test_energy_balance(void)
{
    enum { STEPS = 50 };
    static double samples[7 * (STEPS + 1)], u[STEPS];
    const double x0[2] = {1.2, -0.4};
    double x[2], x1[2], flows[2], h0, h1, defect, sum_defects = 0.0, work = 0.0, loss = 0.0;
    double defects[2], dphi[2];
    chaingen_options options;
    chaingen_stats stats;
    long k;
    int j;
    begin("energy_balance");
    use(full_variant());
    options = tight();
    /* One step: H1 - H0 - (W - D) is the midpoint quadrature error of V, O(dphi^3). */
    for (j = 0; j < 2; ++j) {
        const double dt = j == 0 ? 0.05 : 0.025, tau = 0.7;
        double omega_m;
        chaingen_workspace_init(&model, &ws);
        STATUS(step(x0, tau, dt, x1, flows, &options, NULL), CHAINGEN_OK);
        h0 = pendulum_energy(x0, PENDULUM_STIFFNESS);
        h1 = pendulum_energy(x1, PENDULUM_STIFFNESS);
        defect = pendulum_balance_defect(x0[0], x1[0], PENDULUM_STIFFNESS);
        defects[j] = h1 - h0 - (flows[0] - flows[1]);
        dphi[j] = x1[0] - x0[0];
        omega_m = 0.5 * (x0[1] + x1[1]);
        EXPECT(close_to(defects[j], defect, 1e-13 * (fabs(h0) + fabs(h1) + 1.0)),
               "dt %g: H1 - H0 - (W - D) = %.6e, the quadrature error %.6e", dt, defects[j],
               defect);
        EXPECT(close_to(flows[0], tau * (x1[0] - x0[0]), 1e-14),
               "W %.17g, tau dphi %.17g", flows[0], tau * (x1[0] - x0[0]));
        EXPECT(close_to(flows[1], pendulum_damping() * omega_m * omega_m * dt, 1e-14)
                   && flows[1] > 0.0, "D %.17g", flows[1]);
    }
    /* O(dphi^3): V''' dphi^3 / 24 at leading order, alike at both step lengths. */
    EXPECT(fabs(log(defects[0] / (dphi[0] * dphi[0] * dphi[0])
                    / (defects[1] / (dphi[1] * dphi[1] * dphi[1])))) < log(1.25),
           "defect / dphi^3 at dt and dt/2: %.4e, %.4e", defects[0] / pow(dphi[0], 3.0),
           defects[1] / pow(dphi[1], 3.0));
    /* A run: the sample rows' W and D are the steps' sums. */
    inputs(u, STEPS, 0.02);
    chaingen_workspace_init(&model, &ws);
    memcpy(x, x0, sizeof x);
    for (k = 0; k < STEPS; ++k) {
        STATUS(step(x, u[k], 0.02, x1, flows, &options, NULL), CHAINGEN_OK);
        sum_defects += pendulum_balance_defect(x[0], x1[0], PENDULUM_STIFFNESS);
        work += flows[0];
        loss += flows[1];
        memcpy(x, x1, sizeof x);
    }
    pendulum_knob.calls[PENDULUM_F_ENERGY_TERMS] = 0;
    STATUS(simulate(x0, 0.0, 0.02, STEPS, 1, u, &options, samples, x1, &stats), CHAINGEN_OK);
    /* The energy check evaluates (H, T) at the start once, then at each step's end: a step
     * starting where the last one ended reuses its end's. */
    EXPECT(pendulum_knob.calls[PENDULUM_F_ENERGY_TERMS] == STEPS + 1,
           "energy_terms evaluated %ld times in %d steps",
           pendulum_knob.calls[PENDULUM_F_ENERGY_TERMS], STEPS);
    {
        const double *last = samples + STEPS * model.nsample;
        const double *first = samples;
        EXPECT(close_to(last[5], work, 1e-12) && close_to(last[6], loss, 1e-12),
               "row W %.15g D %.15g, the steps' %.15g %.15g", last[5], last[6], work, loss);
        EXPECT(first[5] == 0.0 && first[6] == 0.0, "row 0's flows are not zero");
        EXPECT(close_to(last[3] - first[3] - (last[5] - last[6]), sum_defects, 1e-11),
               "run's balance %.6e, the quadrature errors' sum %.6e",
               last[3] - first[3] - (last[5] - last[6]), sum_defects);
    }
    end();
}

/* ---- Composition ----------------------------------------------------------------------------- */

/* The final state after `steps` steps of dt from x0 (unactuated run). */
static int run_to(const double *x0, double dt, long steps, const chaingen_options *options,
                  double *x_final)
{
    static double samples[7 * 2];
    chaingen_stats stats;
    return simulate(x0, 0.0, dt, steps, steps > 0 ? steps : 1, NULL, options, samples, x_final,
                    &stats);
}

static double state_error(const double *a, const double *b)
{
    return fmax(fabs(a[0] - b[0]), fabs(a[1] - b[1]));
}

static void test_composition_order(void)
{
    static const int kinds[4] = {PENDULUM_PLAIN, PENDULUM_YOSHIDA4, PENDULUM_SUZUKI4,
                                 PENDULUM_KAHAN_LI6};
    static const char *names[4] = {"midpoint", "yoshida4", "suzuki4", "kahan_li6"};
    static const int orders[4] = {2, 4, 4, 6};
    static const long first_steps[4] = {64, 16, 8, 8};
    const double x0[2] = {1.2, 0.0}, t_end = 2.0;
    double reference[2];
    chaingen_options options;
    int s, j;
    begin("composition_order");
    {
        pendulum_variant v = full_variant();
        v.composition = PENDULUM_KAHAN_LI6;
        use(v);
        options = tight();
        STATUS(run_to(x0, t_end / 800.0, 800, &options, reference), CHAINGEN_OK);
    }
    for (s = 0; s < 4; ++s) {
        pendulum_variant v = full_variant();
        double errors[4], x[2], slope[3], fit, mean_x = 0.0, mean_y = 0.0, sxy = 0.0, sxx = 0.0;
        v.composition = kinds[s];
        use(v);
        options = tight();
        for (j = 0; j < 4; ++j) {
            const long steps = first_steps[s] << j;
            STATUS(run_to(x0, t_end / (double)steps, steps, &options, x), CHAINGEN_OK);
            errors[j] = state_error(x, reference);
        }
        for (j = 0; j < 4; ++j) {
            mean_x += (double)j * log(0.5) / 4.0;
            mean_y += log(errors[j]) / 4.0;
        }
        for (j = 0; j < 4; ++j) {
            const double dx = (double)j * log(0.5) - mean_x, dy = log(errors[j]) - mean_y;
            sxy += dx * dy;
            sxx += dx * dx;
        }
        fit = sxy / sxx;
        for (j = 0; j < 3; ++j) {
            slope[j] = log(errors[j] / errors[j + 1]) / log(2.0);
        }
        printf("# %s: errors %.3e %.3e %.3e %.3e, slopes %.3f %.3f %.3f, fit %.3f\n", names[s],
               errors[0], errors[1], errors[2], errors[3], slope[0], slope[1], slope[2], fit);
        EXPECT(fabs(fit - orders[s]) < 0.05, "%s: order %.3f, expected %d", names[s], fit,
               orders[s]);
        for (j = 0; j < 3; ++j) {
            EXPECT(fabs(slope[j] - orders[s]) < 0.15, "%s: slope %.3f at halving %d", names[s],
                   slope[j], j);
        }
    }
    /* The stages' warm start (each from its own solutions in the previous composed steps)
     * changes the iterations, not the solution; with a poor predictor, it saves many. */
    {
        static double samples[7 * 201];
        pendulum_variant v = full_variant();
        double warm[2], cold[2];
        chaingen_stats warm_stats, cold_stats;
        v.composition = PENDULUM_SUZUKI4;
        use(v);
        pendulum_knob.predictor_bias = 0.3;
        pendulum_knob.cubic = 1e3;
        options = tight();
        STATUS(simulate(x0, 0.0, 0.005, 200, 1, NULL, &options, samples, warm, &warm_stats),
               CHAINGEN_OK);
        options.warm_start = 0;
        STATUS(simulate(x0, 0.0, 0.005, 200, 1, NULL, &options, samples, cold, &cold_stats),
               CHAINGEN_OK);
        EXPECT(state_error(warm, cold) < 1e-9, "composed: warm and cold differ by %.3e",
               state_error(warm, cold));
        printf("# composed warm start: %ld iterations, cold %ld\n", warm_stats.newton_iterations,
               cold_stats.newton_iterations);
        EXPECT(warm_stats.newton_iterations < 0.8 * (double)cold_stats.newton_iterations,
               "composed: warm %ld iterations, cold %ld", warm_stats.newton_iterations,
               cold_stats.newton_iterations);
    }
    /* A composed step's flows are its stages' sum: H1 - H0 - (W - D) stays the sum of the
     * stages' quadrature errors, small. */
    {
        pendulum_variant v = full_variant();
        double x1[2], flows[2], h0, h1;
        v.composition = PENDULUM_YOSHIDA4;
        use(v);
        options = tight();
        STATUS(step(x0, 0.5, 0.01, x1, flows, &options, NULL), CHAINGEN_OK);
        h0 = pendulum_energy(x0, PENDULUM_STIFFNESS);
        h1 = pendulum_energy(x1, PENDULUM_STIFFNESS);
        EXPECT(fabs(h1 - h0 - (flows[0] - flows[1])) < 1e-6 && flows[1] > 0.0,
               "composed balance %.3e", h1 - h0 - (flows[0] - flows[1]));
        EXPECT(close_to(flows[0], 0.5 * (x1[0] - x0[0]), 1e-12),
               "composed W %.17g, tau dphi %.17g", flows[0], 0.5 * (x1[0] - x0[0]));
    }
    end();
}

/* ---- Sensitivities --------------------------------------------------------------------------- */

/* s1 of one step from s0 (x = s) with (tau, k), on a fresh workspace. */
static int fresh_step(const double *s0, double tau, double k, double dt, double *s1)
{
    const double u[1] = {tau}, p[1] = {k};
    chaingen_options options = tight();
    chaingen_workspace_init(&model, &ws);
    return chaingen_step(&model, s0, model.nu ? u : NULL, model.nu, model.np ? p : NULL,
                         model.np, dt, s1, NULL, &options, &ws, NULL);
}

static double matrix_error(const double *a, const double *b, int n, double *scale)
{
    double largest = 0.0, difference = 0.0;
    int i;
    for (i = 0; i < n; ++i) {
        largest = fmax(largest, fabs(b[i]));
        difference = fmax(difference, fabs(a[i] - b[i]));
    }
    *scale = largest;
    return difference / fmax(largest, 1e-300);
}

static double worst_sensitivity;   /* the largest relative difference seen */

static void check_sensitivities(const char *name, double dt)
{
    const double s0[2] = {0.9, -0.6}, tau = 0.4, k = PENDULUM_STIFFNESS;
    const double u[1] = {tau}, p[1] = {k};
    double x1[2], s1[2], ds[4], du[2], dp[2], fd_ds[4], fd_du[2], fd_dp[2], plus[2], minus[2];
    double scale, error;
    chaingen_options options = tight();
    int i, j, iterations = 0;
    chaingen_workspace_init(&model, &ws);
    memset(ds, 0, sizeof ds);
    STATUS(chaingen_step_sensitivities(&model, s0, model.nu ? u : NULL, model.nu,
                                       model.np ? p : NULL, model.np, dt, x1, ds, du, dp,
                                       &options, &ws, &iterations), CHAINGEN_OK);
    EXPECT(iterations > 0, "%s: iterations %d", name, iterations);
    STATUS(fresh_step(s0, tau, k, dt, s1), CHAINGEN_OK);
    EXPECT(close_to(x1[0], s1[0], 1e-13) && close_to(x1[1], s1[1], 1e-13),
           "%s: step_sensitivities' x1 (%.17g, %.17g), step's (%.17g, %.17g)", name, x1[0], x1[1],
           s1[0], s1[1]);
    for (j = 0; j < 2; ++j) {
        const double h = 1e-5;
        double a[2];
        memcpy(a, s0, sizeof a);
        a[j] = s0[j] + h;
        fresh_step(a, tau, k, dt, plus);
        a[j] = s0[j] - h;
        fresh_step(a, tau, k, dt, minus);
        for (i = 0; i < 2; ++i) {
            fd_ds[i + 2 * j] = (plus[i] - minus[i]) / (2.0 * h);
        }
    }
    error = matrix_error(ds, fd_ds, 4, &scale);
    EXPECT(error < 1e-6, "%s: ds_ds off differences by %.2e (relative)", name, error);
    worst_sensitivity = fmax(worst_sensitivity, error);
    if (model.nu) {
        const double h = 1e-5;
        fresh_step(s0, tau + h, k, dt, plus);
        fresh_step(s0, tau - h, k, dt, minus);
        for (i = 0; i < 2; ++i) {
            fd_du[i] = (plus[i] - minus[i]) / (2.0 * h);
        }
        error = matrix_error(du, fd_du, 2, &scale);
        EXPECT(error < 1e-6, "%s: ds_du off differences by %.2e", name, error);
        worst_sensitivity = fmax(worst_sensitivity, error);
    }
    if (model.np) {
        const double h = 1e-5 * k;
        fresh_step(s0, tau, k + h, dt, plus);
        fresh_step(s0, tau, k - h, dt, minus);
        for (i = 0; i < 2; ++i) {
            fd_dp[i] = (plus[i] - minus[i]) / (2.0 * h);
        }
        error = matrix_error(dp, fd_dp, 2, &scale);
        EXPECT(error < 1e-6, "%s: ds_dp off differences by %.2e", name, error);
        worst_sensitivity = fmax(worst_sensitivity, error);
    }
}

static void test_sensitivities(void)
{
    static const int kinds[4] = {PENDULUM_PLAIN, PENDULUM_YOSHIDA4, PENDULUM_SUZUKI4,
                                 PENDULUM_KAHAN_LI6};
    int s, chain;
    begin("sensitivities");
    for (s = 0; s < 4; ++s) {
        for (chain = 0; chain < 2; ++chain) {
            pendulum_variant v = full_variant();
            char name[64];
            if (s == 0 && chain) {
                continue;
            }
            v.composition = kinds[s];
            v.chain_state = chain;
            use(v);
            sprintf(name, "composition %d chain_state %d", kinds[s], chain);
            check_sensitivities(name, 0.05);
        }
    }
    {
        /* No inputs, no parameters: ds_ds alone (ds_du and ds_dp may be NULL). */
        pendulum_variant v = bare_variant();
        const double s0[2] = {0.9, -0.6};
        double x1[2], ds[4];
        int iterations;
        v.sensitivities = 1;
        use(v);
        check_sensitivities("bare", 0.05);
        STATUS(chaingen_step_sensitivities(&model, s0, NULL, 0, NULL, 0, 0.05, x1, ds, NULL,
                                           NULL, NULL, &ws, &iterations), CHAINGEN_OK);
        v.composition = PENDULUM_SUZUKI4;
        use(v);
        check_sensitivities("bare suzuki4", 0.05);
    }
    printf("# sensitivities: largest relative difference from central differences %.2e\n",
           worst_sensitivity);
    {
        /* The sensitivities never split: a step that only its halves solve fails. */
        const double s0[2] = {0.9, -0.6}, u[1] = {0.0};
        double x1[2], ds[4], du[2], dp[2];
        int iterations;
        use(full_variant());
        pendulum_knob.jacobian_scale = 1.0 / 1.9;
        pendulum_knob.above_dt = 0.015;
        STATUS(step(s0, 0.0, 0.02, x1, NULL, NULL, NULL), CHAINGEN_OK);
        STATUS(chaingen_step_sensitivities(&model, s0, u, 1, STIFFNESS, 1, 0.02, x1, ds, du, dp,
                                           NULL, &ws, &iterations), CHAINGEN_NOT_CONVERGED);
    }
    end();
}

/* ---- Adaptive steps -------------------------------------------------------------------------- */

static void test_adaptive(void)
{
    enum { INTERVALS = 20 };
    static double samples[7 * (INTERVALS + 1)];
    static const double tolerances[3] = {1e-4, 1e-6, 1e-8};
    const double x0[2] = {1.2, 0.0}, dt = 0.1;
    double reference[2], x[2], errors[3];
    chaingen_options options;
    chaingen_stats stats;
    int j;
    long k;
    begin("adaptive");
    {
        pendulum_variant v = full_variant();
        v.composition = PENDULUM_KAHAN_LI6;
        use(v);
        options = tight();
        STATUS(run_to(x0, dt * INTERVALS / 1000.0, 1000, &options, reference), CHAINGEN_OK);
    }
    use(full_variant());
    for (j = 0; j < 3; ++j) {
        options = tight();
        options.rtol = tolerances[j];
        options.atol = tolerances[j];
        STATUS(simulate(x0, 1.0, dt, INTERVALS, 1, NULL, &options, samples, x, &stats),
               CHAINGEN_OK);
        errors[j] = state_error(x, reference);
        printf("# adaptive rtol %.0e: error %.3e, %ld accepted, %ld rejected, dt %.3e..%.3e\n",
               tolerances[j], errors[j], stats.accepted_steps, stats.rejected_steps,
               stats.smallest_dt, stats.largest_dt);
        EXPECT(stats.steps == INTERVALS && stats.accepted_steps >= 2 * INTERVALS,
               "rtol %g: %ld steps, %ld accepted", tolerances[j], stats.steps,
               stats.accepted_steps);
        EXPECT(stats.smallest_dt > 0.0 && stats.smallest_dt <= stats.largest_dt
                   && stats.largest_dt <= 0.5 * dt * (1.0 + 1e-12),
               "rtol %g: dt %g..%g", tolerances[j], stats.smallest_dt, stats.largest_dt);
        for (k = 0; k <= INTERVALS; ++k) {
            if (!close_to(samples[k * model.nsample], 1.0 + (double)k * dt, 1e-12)) {
                failf(__LINE__, "row %ld at t = %g", k, samples[k * model.nsample]);
                break;
            }
        }
    }
    EXPECT(errors[1] < errors[0] && errors[2] < errors[1],
           "error does not fall with rtol: %.3e %.3e %.3e", errors[0], errors[1], errors[2]);
    EXPECT(errors[2] < 1e-5, "rtol 1e-8: error %.3e", errors[2]);
    /* Newton fails on long steps: they are refused and retried shorter, the run completes. */
    use(full_variant());
    pendulum_knob.jacobian_scale = 1.0 / 1.9;
    pendulum_knob.above_dt = 0.02;
    options = tight();
    options.rtol = 1e-6;
    options.atol = 1e-6;
    STATUS(simulate(x0, 0.0, dt, INTERVALS, 1, NULL, &options, samples, x, &stats), CHAINGEN_OK);
    EXPECT(stats.rejected_steps > 0 && stats.largest_dt <= 0.02,
           "Newton's refusals: %ld rejected, largest dt %g", stats.rejected_steps,
           stats.largest_dt);
    /* Composed steps adapt too (order 4 error estimate). */
    {
        pendulum_variant v = full_variant();
        v.composition = PENDULUM_SUZUKI4;
        use(v);
        options = tight();
        options.rtol = 1e-8;
        options.atol = 1e-8;
        STATUS(simulate(x0, 0.0, dt, INTERVALS, 1, NULL, &options, samples, x, &stats),
               CHAINGEN_OK);
        EXPECT(state_error(x, reference) < 1e-5, "composed adaptive: error %.3e",
               state_error(x, reference));
        v.error_entries = 1;
        use(v);
        STATUS(simulate(x0, 0.0, dt, INTERVALS, 1, NULL, &options, samples, x, &stats),
               CHAINGEN_OK);
    }
    {
        /* An angle through zero with atol = 0, and an absolute round-off of two machine
         * epsilons in every angle (es takes its angles from coordinates by atan2): the two
         * results differ by that round-off however short the step, rtol |phi| falls below it
         * near phi = 0, and without the error estimate's floor every step was refused down to
         * MIN_STEP_FRACTION dt (STEP_TOO_SMALL in the first interval). */
        const double through_zero[2] = {0.0, 0.5};
        pendulum_variant v = full_variant();
        v.error_entries = 1;   /* the angles alone, as es at order 2 */
        use(v);
        pendulum_knob.angle_kick = 2.0 * DBL_EPSILON;
        options = tight();
        options.rtol = 1e-12;
        options.atol = 0.0;
        STATUS(simulate(through_zero, 0.0, dt, INTERVALS, 1, NULL, &options, samples, x, &stats),
               CHAINGEN_OK);
        printf("# adaptive rtol 1e-12, atol 0, an angle through zero: %ld accepted, %ld "
               "rejected, dt %.3e..%.3e\n", stats.accepted_steps, stats.rejected_steps,
               stats.smallest_dt, stats.largest_dt);
        EXPECT(stats.steps == INTERVALS && stats.smallest_dt > 1e-9,
               "through zero: %ld steps, smallest dt %g", stats.steps, stats.smallest_dt);
    }
    end();
}

/* ---- simulate -------------------------------------------------------------------------------- */

static void test_simulate(void)
{
    enum { STEPS = 10, EVERY = 3 };
    static double u[STEPS], samples[7 * (STEPS + 1)], zeros[STEPS], again[7 * (STEPS + 1)];
    const double x0[2] = {0.7, 0.2};
    double x[2], next[2], x_final[2], row[5], flows[2], work = 0.0, loss = 0.0;
    chaingen_stats stats;
    long k, rows;
    begin("simulate");
    use(full_variant());
    inputs(u, STEPS, 0.01);
    rows = chaingen_sample_count(&model, STEPS, EVERY);
    memset(samples, 0, sizeof samples);
    STATUS(simulate(x0, 0.25, 0.01, STEPS, EVERY, u, NULL, samples, x_final, &stats),
           CHAINGEN_OK);
    EXPECT(rows == 4, "rows %ld", rows);
    EXPECT(stats.steps == STEPS && stats.accepted_steps == STEPS && stats.rejected_steps == 0
               && stats.smallest_dt == 0.01 && stats.largest_dt == 0.01
               && stats.failed_iterations == 0 && stats.newton_iterations >= STEPS
               && stats.max_newton_iterations >= 1
               && stats.max_newton_iterations <= stats.newton_iterations,
           "stats: %ld steps %ld accepted %ld iterations", stats.steps, stats.accepted_steps,
           stats.newton_iterations);
    /* The rows are the outputs of the states step() reaches, every EVERY steps. */
    chaingen_workspace_init(&model, &ws);
    memcpy(x, x0, sizeof x);
    for (k = 0; k <= STEPS; ++k) {
        if (k % EVERY == 0) {
            const double *r = samples + (k / EVERY) * model.nsample;
            STATUS(chaingen_outputs(&model, x, STIFFNESS, 1, row + 1, row + 2, row + 3, row + 4,
                                    &ws), CHAINGEN_OK);
            EXPECT(close_to(r[0], 0.25 + 0.01 * (double)k, 1e-15) && r[1] == row[1]
                       && r[2] == row[2] && r[3] == row[3] && r[4] == row[4]
                       && close_to(r[5], work, 1e-15) && close_to(r[6], loss, 1e-15),
                   "row %ld: (%g %g %g %g %g %g %g)", k / EVERY, r[0], r[1], r[2], r[3], r[4],
                   r[5], r[6]);
        }
        if (k < STEPS) {
            STATUS(step(x, u[k], 0.01, next, flows, NULL, NULL), CHAINGEN_OK);
            work += flows[0];
            loss += flows[1];
            memcpy(x, next, sizeof x);
        }
    }
    EXPECT(x_final[0] == x[0] && x_final[1] == x[1], "x_final is not the last step's state");
    /* u NULL: zero torques. */
    memset(zeros, 0, sizeof zeros);
    STATUS(simulate(x0, 0.0, 0.01, STEPS, 1, zeros, NULL, samples, x_final, &stats),
           CHAINGEN_OK);
    STATUS(simulate(x0, 0.0, 0.01, STEPS, 1, NULL, NULL, again, x, &stats), CHAINGEN_OK);
    EXPECT(!memcmp(samples, again, sizeof(double) * (STEPS + 1) * model.nsample)
               && x[0] == x_final[0] && x[1] == x_final[1], "u NULL is not zero torques");
    /* No step: row 0 and x_final = x0. */
    memset(&stats, 0xff, sizeof stats);
    STATUS(simulate(x0, 3.0, 0.01, 0, 1, NULL, NULL, samples, x_final, &stats), CHAINGEN_OK);
    EXPECT(stats.steps == 0 && stats.newton_iterations == 0 && stats.smallest_dt == 0.0
               && x_final[0] == x0[0] && x_final[1] == x0[1] && samples[0] == 3.0,
           "a run of no step");
    /* NULL x_final and stats. */
    STATUS(simulate(x0, 0.0, 0.01, STEPS, 2, NULL, NULL, samples, NULL, NULL), CHAINGEN_OK);
    /* A failed step stops the run: the steps before it are valid. */
    STATUS(simulate(x0, 0.0, 0.01, STEPS, 1, NULL, NULL, samples, NULL, NULL), CHAINGEN_OK);
    EXPECT(samples[model.nsample + 1] < samples[2 * model.nsample + 1], "phi does not rise");
    pendulum_knob.phi_limited = 1;   /* next_state fails from the state of step 2 on */
    pendulum_knob.phi_limit = 0.5 * (samples[model.nsample + 1] + samples[2 * model.nsample + 1]);
    STATUS(simulate(x0, 0.0, 0.01, STEPS, 1, NULL, NULL, samples, x_final, &stats),
           CHAINGEN_EVALUATION_FAILED);
    EXPECT(stats.steps == 2, "stopped after %ld steps, expected 2", stats.steps);
    EXPECT(close_to(x_final[0], samples[stats.steps * model.nsample + 1], 1e-15),
           "x_final is not the last valid row's state");
    pendulum_knob.phi_limited = 0;
    pendulum_knob.jacobian_scale = 1.0 / 1.9;
    STATUS(simulate(x0, 0.0, 0.01, STEPS, 1, NULL, NULL, samples, x_final, &stats),
           CHAINGEN_NOT_CONVERGED);
    EXPECT(stats.steps == 0 && stats.failed_iterations > 0, "%ld steps, %d failed iterations",
           stats.steps, stats.failed_iterations);
    end();
}

static void test_simulate_observed(void)
{
    enum { STEPS = 12 };
    static double plain[7 * (STEPS + 1)], observed[7 * (STEPS + 1)];
    const double x0[2] = {0.7, 0.2};
    double a[2], b[2];
    chaingen_stats sa, sb;
    chaingen_control control;
    observation o;
    begin("simulate_observed");
    use(full_variant());
    STATUS(simulate(x0, 0.0, 0.01, STEPS, 1, NULL, NULL, plain, a, &sa), CHAINGEN_OK);
    memset(&o, 0, sizeof o);
    o.stop_at = -1;
    memset(&control, 0, sizeof control);
    STATUS(chaingen_simulate_observed(&model, x0, 0.0, 0.01, STEPS, 1, NULL, 1, STIFFNESS, 1,
                                      NULL, &ws, observed, b, &sb, observe, &o, 5, &control),
           CHAINGEN_OK);
    EXPECT(!memcmp(plain, observed, sizeof plain) && a[0] == b[0] && a[1] == b[1],
           "observing changed the run");
    EXPECT(o.calls == STEPS / 5 && o.last == 10, "observer: %ld calls, last at %ld", o.calls,
           o.last);
    EXPECT(control.steps == STEPS && control.stop == 0, "control.steps %ld", control.steps);
    EXPECT(sa.newton_iterations == sb.newton_iterations, "iterations differ");
    end();
}

static void test_simulate_controlled(void)
{
    enum { STEPS = 10, EVERY = 3, HOLD = 2 };
    static double samples[7 * 8], open[7 * 11], torques[8], u[STEPS];
    const double x0[2] = {0.7, 0.2};
    double x_final[2], x_open[2];
    chaingen_stats stats;
    controlling c;
    long k, j;
    begin("simulate_controlled");
    use(full_variant());
    memset(&c, 0, sizeof c);
    c.stop_at = -1;
    c.gain = 2.0;
    for (k = 0; k < 8; ++k) {
        torques[k] = -99.0;
    }
    STATUS(chaingen_simulate_controlled(&model, x0, 0.5, 0.01, STEPS, EVERY, control_law, &c,
                                        HOLD, STIFFNESS, 1, NULL, &ws, samples, torques, x_final,
                                        &stats, NULL), CHAINGEN_OK);
    EXPECT(c.calls == (STEPS + HOLD - 1) / HOLD, "controller calls %ld", c.calls);
    for (j = 0; j < c.calls && j < 64; ++j) {
        EXPECT(c.steps[j] == j * HOLD && close_to(c.times[j], 0.5 + 0.01 * (double)(j * HOLD),
                                                  1e-14),
               "call %ld at step %ld, t %g", j, c.steps[j], c.times[j]);
    }
    EXPECT(c.phi[0] == x0[0] && c.omega[0] == x0[1], "first call's state");
    /* The inputs the controller chose, as an array: the open-loop run is the same. */
    for (k = 0; k < STEPS; ++k) {
        const long call = k / HOLD;
        u[k] = -c.gain * c.phi[call] + 0.1 * (double)(call + 1);
    }
    for (k = 0; k < (STEPS + EVERY - 1) / EVERY; ++k) {
        EXPECT(torques[k] == u[k * EVERY], "torques row %ld: %g, the input of step %ld %g", k,
               torques[k], k * EVERY, u[k * EVERY]);
    }
    EXPECT(torques[(STEPS + EVERY - 1) / EVERY] == -99.0, "torques written past its rows");
    STATUS(simulate(x0, 0.5, 0.01, STEPS, 1, u, NULL, open, x_open, &stats), CHAINGEN_OK);
    EXPECT(x_open[0] == x_final[0] && x_open[1] == x_final[1], "open loop differs");
    for (k = 0; k <= STEPS; k += EVERY) {
        EXPECT(!memcmp(open + k * model.nsample, samples + (k / EVERY) * model.nsample,
                       sizeof(double) * (size_t)model.nsample),
               "row %ld differs from the open loop's", k / EVERY);
    }
    /* The controller sees the sample row's phi (wrapped) and omega. */
    for (j = 1; j < c.calls && j < 64; ++j) {
        EXPECT(c.phi[j] == open[j * HOLD * model.nsample + 1]
                   && c.omega[j] == open[j * HOLD * model.nsample + 2],
               "call %ld's state is not the row's", j);
    }
    /* Adaptive steps and a composed step in closed loop: the same controller calls. */
    {
        pendulum_variant v = full_variant();
        chaingen_options options;
        v.composition = PENDULUM_YOSHIDA4;
        use(v);
        chaingen_default_options(&model, &options);
        options.rtol = 1e-7;
        options.atol = 1e-7;
        memset(&c, 0, sizeof c);
        c.stop_at = -1;
        c.gain = 2.0;
        STATUS(chaingen_simulate_controlled(&model, x0, 0.5, 0.01, STEPS, EVERY, control_law,
                                            &c, HOLD, STIFFNESS, 1, &options, &ws, samples,
                                            torques, x_final, &stats, NULL), CHAINGEN_OK);
        EXPECT(c.calls == (STEPS + HOLD - 1) / HOLD && stats.steps == STEPS
                   && stats.accepted_steps >= 2 * STEPS,
               "adaptive closed loop: %ld calls, %ld steps, %ld accepted", c.calls, stats.steps,
               stats.accepted_steps);
        use(full_variant());
    }
    /* torques NULL, hold larger than the run */
    memset(&c, 0, sizeof c);
    c.stop_at = -1;
    STATUS(chaingen_simulate_controlled(&model, x0, 0.0, 0.01, STEPS, 1, control_law, &c, 100,
                                        STIFFNESS, 1, NULL, &ws, open, NULL, NULL, NULL, NULL),
           CHAINGEN_OK);
    EXPECT(c.calls == 1, "hold 100: %ld calls", c.calls);
    STATUS(chaingen_simulate_controlled(&model, x0, 0.0, 0.01, STEPS, 1, control_law, &c, 0,
                                        STIFFNESS, 1, NULL, &ws, open, NULL, NULL, NULL, NULL),
           CHAINGEN_BAD_ARGUMENT);
    end();
}

/* ---- The controlled step's torque ----------------------------------------------------------- */

static int control_torques(const double *x0, double u0, double dt, double *tau, double *x1,
                           const chaingen_options *options, int *iterations)
{
    const double u[1] = {u0};
    return chaingen_control_torques(&model, x0, u, 1, params(), model.np, dt, tau, x1, options,
                                    &ws, iterations);
}

/* control_torques takes step()'s step (x1 and iterations bitwise step()'s from the same
 * workspace history, warm starts included) and returns applied_torques at its converged z; a
 * step that step() splits is NOT_CONVERGED with tau and x1 untouched; a composed step or a model
 * without the function is UNAVAILABLE; bad arguments as step(). */
/* A law held over the step (held_control) takes fixed steps only: adaptive ones (rtol or atol
 * > 0) would hold it over each adaptive step instead of dt. simulate_observed and
 * simulate_controlled refuse them with BAD_ARGUMENT before any step; without held_control the
 * same options run. */
static void test_held_control(void)
{
    const double p[1] = {PENDULUM_STIFFNESS}, x0[2] = {1.0, 0.5};
    double samples[7 * 8];
    chaingen_stats stats;
    chaingen_options options;
    controlling c;
    int held, tolerance;
    pendulum_variant v = full_variant();
    begin("held_control");
    v.control = 1;
    v.sensitivities = 0;
    for (held = 0; held <= 1; ++held) {
        v.held_control = held;
        use(v);
        for (tolerance = 0; tolerance < 3; ++tolerance) {
            const int want = held && tolerance ? CHAINGEN_BAD_ARGUMENT : CHAINGEN_OK;
            chaingen_default_options(&model, &options);
            options.rtol = tolerance == 1 ? 1e-8 : 0.0;
            options.atol = tolerance == 2 ? 1e-8 : 0.0;
            memset(&stats, 0, sizeof stats);
            STATUS(chaingen_simulate_observed(&model, x0, 0.0, 0.01, 5, 1, NULL, 1, p, 1,
                                              &options, &ws, samples, NULL, &stats, NULL, NULL,
                                              1, NULL), want);
            EXPECT(stats.steps == (want == CHAINGEN_OK ? 5 : 0),
                   "held %d, tolerance %d: %ld steps", held, tolerance, stats.steps);
            memset(&c, 0, sizeof c);
            c.stop_at = -1;
            STATUS(chaingen_simulate_controlled(&model, x0, 0.0, 0.01, 5, 1, control_law, &c, 1,
                                                p, 1, &options, &ws, samples, NULL, NULL,
                                                &stats, NULL), want);
            EXPECT(c.calls == (want == CHAINGEN_OK ? 5 : 0),
                   "held %d, tolerance %d: %ld controller calls", held, tolerance, c.calls);
        }
    }
    end();
}

/* A split step of a held law (held_control) holds the whole step's torque, u - K phi0 at the
 * step's start, over every half: the same as half steps whose inputs carry the difference from
 * the law each would sample at its own start, u - K phi0 + K phi_start (flows their sum). The
 * law without held_control splits as before: each half samples its own start. */
static void test_held_split(void)
{
    const double gain = 4.0, u0 = 0.4, dt = 0.02, x0[2] = {1.0, 0.5};
    double x1[2], flows[2], expected[2], start[2], total[2], half_flows[2], sampled[2];
    double tau[1], t1[2];
    int depth, k, held;
    pendulum_variant v = full_variant();
    begin("held_split");
    v.control = 1;
    v.sensitivities = 0;
    v.held_gain = gain;
    for (held = 0; held <= 1; ++held) {
        v.held_control = held;
        for (depth = 1; depth <= 2; ++depth) {
            const int pieces = 1 << depth;
            const double piece = dt / pieces;
            /* The expected pieces, unsplit (no knobs): a held law's inputs carry the
             * difference from the law at each piece's start; without it, the plain u. */
            use(v);
            memcpy(start, x0, sizeof start);
            total[0] = total[1] = 0.0;
            for (k = 0; k < pieces; ++k) {
                const double u = held ? u0 - gain * x0[0] + gain * start[0] : u0;
                STATUS(step(start, u, piece, expected, half_flows, NULL, NULL), CHAINGEN_OK);
                EXPECT(store->scalars.step_splits == 0, "an expected piece split");
                total[0] += half_flows[0];
                total[1] += half_flows[1];
                memcpy(start, expected, sizeof start);
            }
            /* Newton crawls on steps longer than one piece: the step splits depth deep. */
            use(v);
            pendulum_knob.jacobian_scale = 1.0 / 1.9;
            pendulum_knob.above_dt = 1.5 * piece;
            STATUS(step(x0, u0, dt, x1, flows, NULL, NULL), CHAINGEN_OK);
            EXPECT(store->scalars.step_splits == pieces - 1, "held %d, depth %d: %ld splits",
                   held, depth, store->scalars.step_splits);
            EXPECT(close_to(x1[0], expected[0], 1e-10) && close_to(x1[1], expected[1], 1e-10),
                   "held %d, depth %d: split step (%.15g, %.15g), pieces (%.15g, %.15g)", held,
                   depth, x1[0], x1[1], expected[0], expected[1]);
            EXPECT(close_to(flows[0], total[0], 1e-12) && close_to(flows[1], total[1], 1e-12),
                   "held %d, depth %d: flows (%.15g, %.15g), the pieces' (%.15g, %.15g)", held,
                   depth, flows[0], flows[1], total[0], total[1]);
            if (held) {
                sampled[depth - 1] = x1[0];
            }
        }
    }
    /* The hold moves the end (by 9e-7 rad) beyond the tolerance above: the law sampled at the
     * middle is not the held one. */
    v.held_control = 0;
    use(v);
    pendulum_knob.jacobian_scale = 1.0 / 1.9;
    pendulum_knob.above_dt = 1.5 * dt / 2;
    STATUS(step(x0, u0, dt, t1, NULL, NULL, NULL), CHAINGEN_OK);
    EXPECT(fabs(t1[0] - sampled[0]) > 1e-8, "held and sampled halves agree: %.3g",
           fabs(t1[0] - sampled[0]));
    /* applied_torques of the held law reads x0 and u alone. */
    v.held_control = 1;
    use(v);
    STATUS(control_torques(x0, u0, dt, tau, t1, NULL, NULL), CHAINGEN_OK);
    EXPECT(tau[0] == u0 - gain * x0[0], "tau %.17g", tau[0]);
    end();
}

/* The entry points of one fixed step (step, step_sensitivities, control_torques) take the dt they
 * are given: rtol or atol other than 0 (adaptive steps are simulate's) is BAD_ARGUMENT before any
 * work, outputs untouched, where it was a plain step that said nothing; with both 0, or options
 * NULL, they step. */
static void test_fixed_step_tolerances(void)
{
    const double p[1] = {PENDULUM_STIFFNESS}, u[1] = {0.3}, x0[2] = {1.0, 0.5};
    const double values[] = {1e-8, 1.0, -1e-8, NAN, INFINITY};
    double x1[2], tau[1], ds_ds[4], ds_du[2], ds_dp[2];
    chaingen_options options;
    int k, which, composed;
    pendulum_variant v = full_variant();
    begin("fixed_step_tolerances");
    v.control = 1;
    for (composed = 0; composed <= 1; ++composed) {
        v.composition = composed ? PENDULUM_YOSHIDA4 : PENDULUM_PLAIN;
        use(v);
        for (which = 0; which < 2; ++which) {
            for (k = 0; k < (int)(sizeof values / sizeof values[0]); ++k) {
                long calls;
                chaingen_default_options(&model, &options);
                if (which == 0) {
                    options.rtol = values[k];
                } else {
                    options.atol = values[k];
                }
                x1[0] = x1[1] = tau[0] = ds_ds[0] = 7.0;
                calls = pendulum_knob.calls[PENDULUM_F_RESIDUAL]
                        + pendulum_knob.calls[PENDULUM_F_RESIDUAL_JACOBIAN];
                STATUS(chaingen_step(&model, x0, u, 1, p, 1, 0.01, x1, NULL, &options, &ws,
                                     NULL), CHAINGEN_BAD_ARGUMENT);
                STATUS(chaingen_step_sensitivities(&model, x0, u, 1, p, 1, 0.01, x1, ds_ds,
                                                   ds_du, ds_dp, &options, &ws, NULL),
                       CHAINGEN_BAD_ARGUMENT);
                STATUS(chaingen_control_torques(&model, x0, u, 1, p, 1, 0.01, tau, x1, &options,
                                                &ws, NULL),
                       composed ? CHAINGEN_UNAVAILABLE : CHAINGEN_BAD_ARGUMENT);
                EXPECT(x1[0] == 7.0 && x1[1] == 7.0 && tau[0] == 7.0 && ds_ds[0] == 7.0,
                       "composed %d, %s = %g: outputs written by a refused call", composed,
                       which ? "atol" : "rtol", values[k]);
                EXPECT(pendulum_knob.calls[PENDULUM_F_RESIDUAL]
                           + pendulum_knob.calls[PENDULUM_F_RESIDUAL_JACOBIAN] == calls,
                       "composed %d, %s = %g: Newton ran", composed, which ? "atol" : "rtol",
                       values[k]);
            }
        }
        chaingen_default_options(&model, &options);
        STATUS(chaingen_step(&model, x0, u, 1, p, 1, 0.01, x1, NULL, &options, &ws, NULL),
               CHAINGEN_OK);
        STATUS(chaingen_step(&model, x0, u, 1, p, 1, 0.01, x1, NULL, NULL, &ws, NULL),
               CHAINGEN_OK);
        STATUS(chaingen_step_sensitivities(&model, x0, u, 1, p, 1, 0.01, x1, ds_ds, ds_du, ds_dp,
                                           &options, &ws, NULL), CHAINGEN_OK);
        if (!composed) {
            STATUS(chaingen_control_torques(&model, x0, u, 1, p, 1, 0.01, tau, x1, &options,
                                            &ws, NULL), CHAINGEN_OK);
        }
    }
    end();
}

static void test_control_torques(void)
{
    enum { STEPS = 6 };
    const double p[1] = {PENDULUM_STIFFNESS}, u[1] = {0.3}, x0[2] = {1.0, 0.5};
    const double bad_x[2] = {NAN, 0.0};
    double controlled[STEPS + 1][2], stepped[STEPS + 1][2], tau[STEPS], x1[2], y1[2], t1;
    int k, its[2][STEPS], iterations = -1;
    pendulum_variant v = full_variant();
    chaingen_options options;
    begin("control_torques");
    v.control = 1;
    v.sensitivities = 0;
    use(v);
    memcpy(controlled[0], x0, sizeof x0);
    memcpy(stepped[0], x0, sizeof x0);
    for (k = 0; k < STEPS; ++k) {
        STATUS(control_torques(controlled[k], 0.3, 0.01, &tau[k], controlled[k + 1], NULL,
                               &its[0][k]), CHAINGEN_OK);
    }
    EXPECT(store->scalars.history == CHAINGEN_WARM_START_HISTORY,
           "the steps' solutions were not kept for the warm start (history %d)",
           store->scalars.history);
    use(v);
    for (k = 0; k < STEPS; ++k) {
        STATUS(step(stepped[k], 0.3, 0.01, stepped[k + 1], NULL, NULL, &its[1][k]),
               CHAINGEN_OK);
    }
    for (k = 0; k < STEPS; ++k) {
        /* z = (dphi, domega) with x1 = (phi0 + dt omega_m, omega0 + domega). */
        const double expected = 0.3 + 0.01 * (stepped[k + 1][1] - stepped[k][1])
                                + stepped[k][0] * stepped[k][0];
        EXPECT(!memcmp(controlled[k + 1], stepped[k + 1], sizeof x1) && its[0][k] == its[1][k],
               "step %d: x1 (%.17g, %.17g) after %d iterations, step() (%.17g, %.17g) after %d",
               k, controlled[k + 1][0], controlled[k + 1][1], its[0][k], stepped[k + 1][0],
               stepped[k + 1][1], its[1][k]);
        EXPECT(close_to(tau[k], expected, 1e-13), "step %d: tau %.17g, expected %.17g", k,
               tau[k], expected);
    }
    /* Newton crawls on steps longer than 0.015 s: step() splits them, control_torques refuses. */
    pendulum_knob.jacobian_scale = 1.0 / 1.9;
    pendulum_knob.above_dt = 0.015;
    x1[0] = x1[1] = t1 = 7.0;
    STATUS(control_torques(x0, 0.3, 0.02, &t1, x1, NULL, &iterations), CHAINGEN_NOT_CONVERGED);
    EXPECT(x1[0] == 7.0 && x1[1] == 7.0 && t1 == 7.0, "outputs written by a refused step");
    EXPECT(iterations == 20 && store->scalars.step_splits == 0, "%d iterations, %ld splits",
           iterations, store->scalars.step_splits);
    STATUS(step(x0, 0.3, 0.02, y1, NULL, NULL, NULL), CHAINGEN_OK);
    EXPECT(store->scalars.step_splits == 1, "step() split it %ld times",
           store->scalars.step_splits);
    pendulum_knob.jacobian_scale = 0.0;
    pendulum_knob.above_dt = 0.0;
    /* A converged step that jumps in energy: step() splits it, control_torques refuses it with
     * the whole step's own status (it said NOT_CONVERGED, "max_iterations reached"). */
    pendulum_knob.energy_jump = 1e4;
    STATUS(control_torques(x0, 0.3, 0.01, &t1, x1, NULL, NULL), CHAINGEN_ENERGY_JUMP);
    EXPECT(x1[0] == 7.0 && x1[1] == 7.0 && t1 == 7.0, "outputs written by a refused step");
    pendulum_knob.energy_jump = 0.0;
    /* A failed evaluation of the torques, and NaN torques: outputs untouched. */
    pendulum_knob.fail_mask = 1u << PENDULUM_F_APPLIED_TORQUES;
    STATUS(control_torques(x0, 0.3, 0.01, &t1, x1, NULL, NULL), CHAINGEN_EVALUATION_FAILED);
    pendulum_knob.fail_mask = 0;
    pendulum_knob.nan_torques = 1;
    STATUS(control_torques(x0, 0.3, 0.01, &t1, x1, NULL, NULL), CHAINGEN_NONFINITE);
    EXPECT(x1[0] == 7.0 && x1[1] == 7.0 && t1 == 7.0, "outputs written by a failed call");
    pendulum_knob.nan_torques = 0;
    /* Bad arguments, as step(). */
    chaingen_default_options(&model, &options);
    STATUS(chaingen_control_torques(&model, NULL, u, 1, p, 1, 0.01, &t1, x1, NULL, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_control_torques(&model, bad_x, u, 1, p, 1, 0.01, &t1, x1, NULL, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_control_torques(&model, x0, u, 1, p, 1, 0.01, NULL, x1, NULL, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_control_torques(&model, x0, u, 1, p, 1, 0.01, &t1, NULL, NULL, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_control_torques(&model, x0, u, 1, p, 1, -0.01, &t1, x1, NULL, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_control_torques(&model, x0, u, 1, p, 1, NAN, &t1, x1, NULL, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_control_torques(&model, x0, NULL, 1, p, 1, 0.01, &t1, x1, NULL, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_control_torques(&model, x0, u, 2, p, 1, 0.01, &t1, x1, NULL, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_control_torques(&model, x0, u, 1, p, 0, 0.01, &t1, x1, NULL, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    STATUS(chaingen_control_torques(&model, x0, u, 1, p, 1, 0.01, &t1, x1, NULL, NULL, NULL),
           CHAINGEN_BAD_ARGUMENT);
    options.reuse_jacobian = -1;
    STATUS(chaingen_control_torques(&model, x0, u, 1, p, 1, 0.01, &t1, x1, &options, &ws, NULL),
           CHAINGEN_BAD_ARGUMENT);
    EXPECT(x1[0] == 7.0 && x1[1] == 7.0 && t1 == 7.0, "outputs written by a refused call");
    /* Without the function, and for a composed step: UNAVAILABLE. */
    use(full_variant());
    STATUS(chaingen_control_torques(&model, x0, u, 1, p, 1, 0.01, &t1, x1, NULL, &ws, NULL),
           CHAINGEN_UNAVAILABLE);
    v.composition = PENDULUM_YOSHIDA4;
    use(v);
    STATUS(chaingen_control_torques(&model, x0, u, 1, p, 1, 0.01, &t1, x1, NULL, &ws, NULL),
           CHAINGEN_UNAVAILABLE);
    EXPECT(x1[0] == 7.0 && x1[1] == 7.0 && t1 == 7.0, "outputs written by an unavailable call");
    end();
}

static void test_every_status(void)
{
    int status;
    begin("every_status");
    for (status = CHAINGEN_OK; status <= CHAINGEN_UNAVAILABLE; ++status) {
        EXPECT(seen[status], "no call produced status %d", status);
    }
    end();
}

/* ---- main ------------------------------------------------------------------------------------ */

typedef struct {
    const char *name;
    void (*run)(void);
} test_group;

static const test_group groups[] = {
    {"sizes", test_sizes},
    {"dimension", test_dimension},
    {"default_options", test_default_options},
    {"workspace_init", test_workspace_init},
    {"sample_count", test_sample_count},
    {"basic_calls", test_basic_calls},
    {"status_bad_argument", test_bad_argument},
    {"status_bad_parameter", test_bad_parameter},
    {"derived_parameters", test_derived_parameters},
    {"status_evaluation_failed", test_evaluation_failed},
    {"status_nonfinite", test_nonfinite},
    {"status_singular_jacobian", test_singular},
    {"status_not_converged", test_not_converged},
    {"diverged", test_diverged},
    {"status_segment_collapsed", test_segment_collapsed},
    {"status_interrupted", test_interrupted},
    {"status_step_too_small", test_step_too_small},
    {"status_energy_jump", test_energy_jump},
    {"status_unavailable", test_unavailable},
    {"newton_modes", test_newton_modes},
    {"round_off_floor", test_round_off_floor},
    {"full_newton_fallback", test_fallback},
    {"warm_start", test_warm_start},
    {"workspace_copy", test_workspace_copy},
    {"split_steps", test_split_steps},
    {"energy_balance", test_energy_balance},
    {"composition_order", test_composition_order},
    {"sensitivities", test_sensitivities},
    {"adaptive", test_adaptive},
    {"simulate", test_simulate},
    {"simulate_observed", test_simulate_observed},
    {"simulate_controlled", test_simulate_controlled},
    {"control_torques", test_control_torques},
    {"held_control", test_held_control},
    {"held_split", test_held_split},
    {"fixed_step_tolerances", test_fixed_step_tolerances},
};

int main(int argc, char **argv)
{
    const size_t count = sizeof groups / sizeof groups[0];
    size_t i;
    int a, all = argc < 2;
    store = (storage *)malloc(sizeof *store);
    if (store) {
        store->ints = NULL;
        store->doubles = NULL;
    }
    if (!store) {
        printf("FAIL main: out of memory\n");
        return 2;
    }
    for (a = 1; a < argc; ++a) {
        int known = 0;
        for (i = 0; i < count; ++i) {
            known |= !strcmp(argv[a], groups[i].name);
        }
        if (!known && strcmp(argv[a], "every_status")) {
            printf("FAIL main: no test group %s\n", argv[a]);
            ++total_failures;
        }
    }
    for (i = 0; i < count; ++i) {
        int selected = all;
        for (a = 1; a < argc; ++a) {
            selected |= !strcmp(argv[a], groups[i].name);
        }
        if (selected) {
            groups[i].run();
        }
    }
    if (all) {
        test_every_status();
    }
    free(store->ints);
    free(store->doubles);
    free(store);
    printf("%s: %d failure(s)\n", total_failures ? "FAILED" : "PASSED", total_failures);
    return total_failures ? 1 : 0;
}

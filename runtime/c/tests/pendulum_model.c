/* The pendulum of pendulum_model.h: its model functions, written by hand in CasADi's calling
 * convention (inputs and outputs by position, NULL outputs skipped), and the chaingen_model that
 * points at them. */
#include "pendulum_model.h"

#include <math.h>
#include <stddef.h>
#include <string.h>

pendulum_knobs pendulum_knob;

/* The variant the functions evaluate, and what follows from it. */
static struct {
    pendulum_variant variant;
    int nu, np;
    double c;          /* damping */
    double ax, ay;     /* anchor */
    double l0;         /* rest length */
    double size;       /* the geometry's size: L + |A| */
} config;

#define TWO_PI 6.283185307179586
#define PI 3.141592653589793

/* Yoshida's triple jump, Suzuki's fractal composition, Kahan and Li's s9odr6a. */
static double yoshida4[3];
static double suzuki4[5];
static const double kahan_li6[9] = {
    0.39216144400731413928, 0.33259913678935943860, -0.70624617255763935981,
    0.08221359629355080023, 0.79854399093482996340, 0.08221359629355080023,
    -0.70624617255763935981, 0.33259913678935943860, 0.39216144400731413928};
static const double p_lower[1] = {0.0};
static const int p_inclusive[1] = {0};

void pendulum_knobs_reset(void)
{
    memset(&pendulum_knob, 0, sizeof pendulum_knob);
}

double pendulum_damping(void)
{
    return config.c;
}

void pendulum_potential(double phi, double k, double out[4])
{
    const double s = sin(phi), c = cos(phi);
    const double mgl = PENDULUM_MASS * PENDULUM_GRAVITY * PENDULUM_LENGTH;
    const double rx = PENDULUM_LENGTH * s, ry = -PENDULUM_LENGTH * c;   /* r */
    const double dx = PENDULUM_LENGTH * c, dy = PENDULUM_LENGTH * s;    /* r' */
    const double ex = rx - config.ax, ey = ry - config.ay;               /* e = r - A */
    const double d = sqrt(ex * ex + ey * ey);
    const double er1 = ex * dx + ey * dy;                                /* e . r' */
    const double er2 = -ex * rx - ey * ry;                               /* e . r'' (r'' = -r) */
    const double l2 = PENDULUM_LENGTH * PENDULUM_LENGTH;                 /* r' . r' */
    double spring, slope, curvature;
    if (config.l0 == 0.0) {
        /* k/2 d^2: smooth through d = 0. */
        spring = 0.5 * (ex * ex + ey * ey);
        slope = er1;
        curvature = l2 + er2;
    } else {
        const double d1 = er1 / d;                                /* d' */
        const double d2 = (l2 + er2) / d - d1 * d1 / d;           /* d'' */
        spring = 0.5 * (d - config.l0) * (d - config.l0);
        slope = (d - config.l0) * d1;
        curvature = d1 * d1 + (d - config.l0) * d2;
    }
    out[0] = -mgl * c + k * spring;
    out[1] = mgl * s + k * slope;
    out[2] = mgl * c + k * curvature;
    out[3] = slope;
}

static double inertia(void)
{
    return PENDULUM_MASS * PENDULUM_LENGTH * PENDULUM_LENGTH;
}

double pendulum_energy(const double *x, double k)
{
    double v[4];
    pendulum_potential(x[0], k, v);
    return 0.5 * inertia() * x[1] * x[1] + v[0];
}

double pendulum_balance_defect(double phi0, double phi1, double k)
{
    double v0[4], v1[4], vm[4];
    pendulum_potential(phi0, k, v0);
    pendulum_potential(phi1, k, v1);
    pendulum_potential(0.5 * (phi0 + phi1), k, vm);
    return v1[0] - v0[0] - vm[1] * (phi1 - phi0);
}

/* ---- Argument positions ---------------------------------------------------------------------- */

/* (z, x0, [u], [q], dt): u, q and dt of a step function's arguments. The torque: u, and with
 * held_gain the held law's -K phi0 added. */
static double step_u(const double **arg)
{
    const double u = config.nu ? (arg[2] ? arg[2][0] : 0.0) : 0.0;
    return u - config.variant.held_gain * arg[1][0];
}

static double step_k(const double **arg)
{
    return config.np ? arg[2 + (config.nu > 0)][0] : PENDULUM_STIFFNESS;
}

static double step_dt(const double **arg)
{
    return arg[2 + (config.nu > 0) + (config.np > 0)][0];
}

/* (x, [q], ...): k from q at position `at`. */
static double k_at(const double **arg, int at)
{
    return config.np ? arg[at][0] : PENDULUM_STIFFNESS;
}

/* Count an evaluation; 1 when the knobs make it fail (dt: the step's, or HUGE_VAL for a function
 * without one). */
static int enter(int function, double dt)
{
    ++pendulum_knob.calls[function];
    return (pendulum_knob.fail_mask & (1u << function)) && fabs(dt) > pendulum_knob.above_dt;
}

static int knob_active(double dt)
{
    return fabs(dt) > pendulum_knob.above_dt;
}

/* ---- The model functions ------------------------------------------------------------------- */

static int f_parameters(const double **arg, double **res, long long int *iw, double *w, int mem)
{
    (void)iw, (void)w, (void)mem;
    if (enter(PENDULUM_F_PARAMETERS, HUGE_VAL)) {
        return 1;
    }
    if (res[0]) {
        res[0][0] = arg[0][0];
    }
    return 0;
}

static int f_initial_state(const double **arg, double **res, long long int *iw, double *w,
                           int mem)
{
    (void)iw, (void)w, (void)mem;
    if (enter(PENDULUM_F_INITIAL_STATE, HUGE_VAL)) {
        return 1;
    }
    if (res[0]) {
        res[0][0] = arg[0][0];
        res[0][1] = arg[1][0];
    }
    return 0;
}

static int f_outputs(const double **arg, double **res, long long int *iw, double *w, int mem)
{
    const double *x = arg[0];
    (void)iw, (void)w, (void)mem;
    if (enter(PENDULUM_F_OUTPUTS, HUGE_VAL)) {
        return 1;
    }
    if (res[0]) {
        res[0][0] = x[0] - TWO_PI * ceil((x[0] - PI) / TWO_PI);   /* (-pi, pi] */
    }
    if (res[1]) {
        res[1][0] = x[1];
    }
    if (res[2]) {
        res[2][0] = pendulum_energy(x, k_at(arg, 1));
    }
    if (res[3]) {
        const double rx = PENDULUM_LENGTH * sin(x[0]), ry = -PENDULUM_LENGTH * cos(x[0]);
        res[3][0] = sqrt(rx * rx + ry * ry) - PENDULUM_LENGTH;
    }
    return 0;
}

static int f_holding_torques(const double **arg, double **res, long long int *iw, double *w,
                             int mem)
{
    double v[4];
    (void)iw, (void)w, (void)mem;
    if (enter(PENDULUM_F_HOLDING_TORQUES, HUGE_VAL)) {
        return 1;
    }
    pendulum_potential(arg[0][0], k_at(arg, 1), v);
    if (res[0]) {
        res[0][0] = v[1];
    }
    return 0;
}

/* F and dF/dz at (z, x0, u, k, dt). */
static void residual_at(const double **arg, double *f, double *jacobian)
{
    const double *z = arg[0], *x0 = arg[1];
    const double tau = step_u(arg), k = step_k(arg), dt = step_dt(arg);
    const double omega_m = x0[1] + 0.5 * z[1];
    double v[4], f1, cubic;
    pendulum_potential(x0[0] + 0.5 * z[0], k, v);
    f1 = inertia() * z[1] + dt * (v[1] - tau + config.c * omega_m);
    cubic = 1.0 + 3.0 * pendulum_knob.cubic * f1 * f1;   /* d(F1 + cubic F1^3)/dF1 */
    if (f) {
        f[0] = z[0] - dt * omega_m;
        f[1] = f1 + pendulum_knob.cubic * f1 * f1 * f1;
        if (pendulum_knob.residual_noise != 0.0) {
            /* A linear congruential sequence in [-1, 1), one draw per evaluation. */
            static const double scale = 1.0 / 2147483648.0;
            pendulum_knob.noise_state = pendulum_knob.noise_state * 1103515245u + 12345u;
            f[1] += pendulum_knob.residual_noise
                    * ((double)(pendulum_knob.noise_state & 0x7fffffffu) * scale * 2.0 - 1.0);
        }
        if (pendulum_knob.fold > 0.0 && knob_active(dt)) {
            f[1] = f1 * f1 + pendulum_knob.fold;
        }
        if (pendulum_knob.nan_residual == 1 && knob_active(dt)) {
            f[1] = NAN;
        }
    }
    if (jacobian) {
        double scale = pendulum_knob.jacobian_scale != 0.0 && knob_active(dt)
                           ? pendulum_knob.jacobian_scale : 1.0;
        if (pendulum_knob.zero_jacobian && knob_active(dt)) {
            scale = 0.0;
        }
        if (pendulum_knob.fold > 0.0 && knob_active(dt)) {
            cubic *= 2.0 * f1;   /* d(F1^2 + fold)/dF1 */
        }
        jacobian[0] = scale * 1.0;
        jacobian[1] = scale * cubic * 0.5 * dt * v[2];
        jacobian[2] = scale * -0.5 * dt;
        jacobian[3] = scale * cubic * (inertia() + 0.5 * dt * config.c);
    }
}

static int f_residual(const double **arg, double **res, long long int *iw, double *w, int mem)
{
    const double dt = step_dt(arg);
    (void)iw, (void)w, (void)mem;
    if (enter(PENDULUM_F_RESIDUAL, dt)) {
        return 1;
    }
    residual_at(arg, res[0], NULL);
    if (res[0] && pendulum_knob.nan_residual == 2 && knob_active(dt)) {
        res[0][1] = NAN;
    }
    return 0;
}

static int f_residual_jacobian(const double **arg, double **res, long long int *iw, double *w,
                               int mem)
{
    (void)iw, (void)w, (void)mem;
    if (enter(PENDULUM_F_RESIDUAL_JACOBIAN, step_dt(arg))) {
        return 1;
    }
    residual_at(arg, res[0], res[1]);
    return 0;
}

/* (x0, [q], dt) -> z: explicit Euler in omega without the torque, then the midpoint's dphi. */
static int f_predictor(const double **arg, double **res, long long int *iw, double *w, int mem)
{
    const double *x0 = arg[0];
    const double k = k_at(arg, 1), dt = arg[1 + (config.np > 0)][0];
    double v[4];
    (void)iw, (void)w, (void)mem;
    if (enter(PENDULUM_F_PREDICTOR, dt)) {
        return 1;
    }
    pendulum_potential(x0[0], k, v);
    if (res[0]) {
        const double b = dt * (-v[1] - config.c * x0[1]) / inertia();
        res[0][1] = b + pendulum_knob.predictor_bias;
        res[0][0] = dt * (x0[1] + 0.5 * b);
    }
    return 0;
}

static int f_next_state(const double **arg, double **res, long long int *iw, double *w, int mem)
{
    const double *z = arg[0], *x0 = arg[1];
    const double tau = step_u(arg), dt = step_dt(arg);
    const double omega_m = x0[1] + 0.5 * z[1];
    (void)iw, (void)w, (void)mem;
    if (enter(PENDULUM_F_NEXT_STATE, dt)
        || (pendulum_knob.phi_limited && x0[0] > pendulum_knob.phi_limit)) {
        return 1;
    }
    if (res[0]) {
        res[0][0] = x0[0] + dt * omega_m + pendulum_knob.angle_kick;
        res[0][1] = x0[1] + z[1] + pendulum_knob.state_kick;
    }
    if (config.variant.flows && res[1]) {
        res[1][0] = tau * dt * omega_m;
        res[1][1] = config.c * omega_m * omega_m * dt;
    }
    return 0;
}

/* (z, x0, [u], [q], dt) -> tau = u + dt domega + phi0^2, the control variant's applied torque;
 * with held_gain the step's torque u - K phi0. */
static int f_applied_torques(const double **arg, double **res, long long int *iw, double *w,
                             int mem)
{
    const double *z = arg[0], *x0 = arg[1];
    const double dt = step_dt(arg);
    (void)iw, (void)w, (void)mem;
    if (enter(PENDULUM_F_APPLIED_TORQUES, dt)) {
        return 1;
    }
    if (res[0]) {
        res[0][0] = pendulum_knob.nan_torques ? NAN
                    : config.variant.held_gain != 0.0 ? step_u(arg)
                    : step_u(arg) + dt * z[1] + x0[0] * x0[0];
    }
    return 0;
}

/* (x0, x1, [q]) -> (length / (tolerance G), cos of the segment's turn). */
static int f_segment_margins(const double **arg, double **res, long long int *iw, double *w,
                             int mem)
{
    const double *x0 = arg[0], *x1 = arg[1];
    const double e0x = PENDULUM_LENGTH * sin(x0[0]) - config.ax;
    const double e0y = -PENDULUM_LENGTH * cos(x0[0]) - config.ay;
    const double e1x = PENDULUM_LENGTH * sin(x1[0]) - config.ax;
    const double e1y = -PENDULUM_LENGTH * cos(x1[0]) - config.ay;
    const double d0 = sqrt(e0x * e0x + e0y * e0y), d1 = sqrt(e1x * e1x + e1y * e1y);
    (void)iw, (void)w, (void)mem;
    if (enter(PENDULUM_F_SEGMENT_MARGINS, HUGE_VAL)) {
        return 1;
    }
    if (res[0]) {
        res[0][0] = d1 / (PENDULUM_RUN_TOLERANCE * config.size);
        res[0][1] = (e0x * e1x + e0y * e1y) / (d0 * d1);
    }
    return 0;
}

static int f_energy_terms(const double **arg, double **res, long long int *iw, double *w,
                          int mem)
{
    const double *x = arg[0];
    (void)iw, (void)w, (void)mem;
    if (enter(PENDULUM_F_ENERGY_TERMS, HUGE_VAL)) {
        return 1;
    }
    if (res[0]) {
        double v[4];
        pendulum_potential(x[0], k_at(arg, 1), v);
        res[0][0] = pendulum_energy(x, k_at(arg, 1)) + pendulum_knob.energy_jump * x[0];
        res[0][1] = 0.5 * inertia() * x[1] * x[1];
        res[0][2] = res[0][1] + fabs(v[0]) + pendulum_knob.energy_cancelled;
    }
    return 0;
}

/* R = [dF/ds0 dF/du dF/dp] (NZ x (2 + nu + np)), column-major. */
static int f_sensitivity_rhs(const double **arg, double **res, long long int *iw, double *w,
                             int mem)
{
    const double *z = arg[0], *x0 = arg[1];
    const double k = step_k(arg), dt = step_dt(arg);
    double v[4], *r = res[0];
    int column = 2;
    (void)iw, (void)w, (void)mem;
    if (enter(PENDULUM_F_SENSITIVITY_RHS, dt)) {
        return 1;
    }
    if (!r) {
        return 0;
    }
    pendulum_potential(x0[0] + 0.5 * z[0], k, v);
    r[0] = 0.0;                         /* d/dphi0 */
    r[1] = dt * v[2];
    r[2] = -dt;                         /* d/domega0 */
    r[3] = dt * config.c;
    if (config.nu) {                    /* d/dtau */
        r[2 * column] = 0.0;
        r[2 * column + 1] = -dt;
        ++column;
    }
    if (config.np) {                    /* d/dk */
        r[2 * column] = 0.0;
        r[2 * column + 1] = dt * v[3];
    }
    return 0;
}

/* (S_z, S_s0, [S_u], [S_p]): the partial derivatives of s1 = next_state. */
static int f_sensitivity_map(const double **arg, double **res, long long int *iw, double *w,
                             int mem)
{
    const double dt = step_dt(arg);
    (void)iw, (void)w, (void)mem;
    if (enter(PENDULUM_F_SENSITIVITY_MAP, dt)) {
        return 1;
    }
    if (res[0]) {                       /* ds1/dz: 2 x 2 */
        res[0][0] = 0.0;
        res[0][1] = 0.0;
        res[0][2] = 0.5 * dt;
        res[0][3] = 1.0;
    }
    if (res[1]) {                       /* ds1/ds0 */
        res[1][0] = 1.0;
        res[1][1] = 0.0;
        res[1][2] = dt;
        res[1][3] = 1.0;
    }
    if (config.nu && res[2]) {
        res[2][0] = 0.0;
        res[2][1] = 0.0;
    }
    if (config.np && res[2 + (config.nu > 0)]) {
        res[2 + (config.nu > 0)][0] = 0.0;
        res[2 + (config.nu > 0)][1] = 0.0;
    }
    return 0;
}

/* (x0, x1, [q]) -> (dx0/ds0, ds1/dx1, [dx0/dp, ds1/dp]): x is s. */
static int f_joint_maps(const double **arg, double **res, long long int *iw, double *w, int mem)
{
    int i;
    (void)arg, (void)iw, (void)w, (void)mem;
    if (enter(PENDULUM_F_JOINT_MAPS, HUGE_VAL)) {
        return 1;
    }
    for (i = 0; i < 2; ++i) {
        if (res[i]) {
            res[i][0] = 1.0;
            res[i][1] = 0.0;
            res[i][2] = 0.0;
            res[i][3] = 1.0;
        }
    }
    if (config.np) {
        for (i = 2; i < 4; ++i) {
            if (res[i]) {
                res[i][0] = 0.0;
                res[i][1] = 0.0;
            }
        }
    }
    return 0;
}

/* ---- The model ------------------------------------------------------------------------------ */

void pendulum_model_init(chaingen_model *model, const pendulum_variant *variant)
{
    const double cube = pow(2.0, 1.0 / 3.0), root4 = pow(4.0, 1.0 / 3.0);
    const double p4 = 1.0 / (4.0 - root4);
    pendulum_knobs_reset();
    yoshida4[0] = yoshida4[2] = 1.0 / (2.0 - cube);
    yoshida4[1] = -cube / (2.0 - cube);
    suzuki4[0] = suzuki4[1] = suzuki4[3] = suzuki4[4] = p4;
    suzuki4[2] = 1.0 - 4.0 * p4;

    memset(&config, 0, sizeof config);
    config.variant = *variant;
    config.nu = variant->actuated ? 1 : 0;
    config.np = variant->parameters ? 1 : 0;
    config.c = variant->damped ? PENDULUM_DAMPING : 0.0;
    if (variant->collapse) {
        config.ax = PENDULUM_LENGTH * sin(PENDULUM_COLLAPSE_ANGLE);
        config.ay = -PENDULUM_LENGTH * cos(PENDULUM_COLLAPSE_ANGLE);
        config.l0 = 0.0;
    } else {
        config.ax = 1.5;
        config.ay = 0.0;
        config.l0 = 0.5;
    }
    config.size = PENDULUM_LENGTH + sqrt(config.ax * config.ax + config.ay * config.ay);

    memset(model, 0, sizeof *model);
    model->n_joints = PENDULUM_N;
    model->nx = PENDULUM_NX;
    model->nz = PENDULUM_NZ;
    model->nu = config.nu;
    model->np = config.np;
    model->nq = config.np;
    model->nconstraint = PENDULUM_NCONSTRAINT;
    model->nsample = 3 + 2 * PENDULUM_N + (variant->flows ? 2 : 0);
    model->nsegment = variant->segments ? 1 : 0;
    switch (variant->composition) {
    case PENDULUM_YOSHIDA4:
        model->order = 4;
        model->nstage = 3;
        model->stages = yoshida4;
        break;
    case PENDULUM_SUZUKI4:
        model->order = 4;
        model->nstage = 5;
        model->stages = suzuki4;
        break;
    case PENDULUM_KAHAN_LI6:
        model->order = 6;
        model->nstage = 9;
        model->stages = kahan_li6;
        break;
    default:
        model->order = 2;
        model->nstage = 0;
        model->stages = NULL;
        break;
    }
    model->error_entries = variant->error_entries ? variant->error_entries : 2 * PENDULUM_N;
    model->flows = variant->flows;
    model->energy_check = variant->energy_check;
    model->sensitivities = variant->sensitivities;
    model->chain_state = variant->chain_state;
    model->held_control = variant->held_control;
    model->start_margin = PENDULUM_START_TOLERANCE / PENDULUM_RUN_TOLERANCE;
    model->p_lower = config.np ? p_lower : NULL;
    model->p_inclusive = config.np ? p_inclusive : NULL;
    model->arm_nh = 0;
    model->arm_h_row = NULL;
    model->arm_h_col = NULL;
    model->defaults.max_iterations = 20;
    model->defaults.update_rtol = 1e-10;
    model->defaults.update_atol = 1e-13;
    model->defaults.residual_tol = 1e-8;
    model->defaults.warm_start = 1;
    model->defaults.reuse_jacobian = CHAINGEN_JACOBIAN_EVERY_ITERATE;
    model->defaults.energy_tol = variant->energy_check ? 0.01 : 0.0;
    model->defaults.rtol = 0.0;
    model->defaults.atol = 0.0;
    model->parameters = config.np ? f_parameters : NULL;
    model->initial_state = f_initial_state;
    model->outputs = f_outputs;
    model->holding_torques = variant->holding ? f_holding_torques : NULL;
    model->residual = f_residual;
    model->residual_jacobian = f_residual_jacobian;
    model->newton_factors = NULL;
    model->predictor = f_predictor;
    model->next_state = f_next_state;
    model->segment_margins = variant->segments ? f_segment_margins : NULL;
    model->energy_terms = variant->energy_check ? f_energy_terms : NULL;
    model->sensitivity_rhs = variant->sensitivities ? f_sensitivity_rhs : NULL;
    model->sensitivity_map = variant->sensitivities ? f_sensitivity_map : NULL;
    model->applied_torques = variant->control ? f_applied_torques : NULL;
    model->joint_maps = variant->sensitivities && variant->chain_state && model->nstage > 0
                            ? f_joint_maps : NULL;
}

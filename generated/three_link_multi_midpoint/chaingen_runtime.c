/* chaingen's C runtime: the solver algorithms of every generated package, written once.
 *
 * A port of the solver the templates used to render per scene (templates/solver.c.j2): the same
 * floating-point operations in the same order, so a package's results are bitwise those of the
 * rendered solver. Where the rendered solver branched on the scene's features at generation
 * time (inputs, parameters, spring segments, energy flows, the energy check, a composed step, the
 * arm solve, sensitivities), this file branches at run time on the fields of the model
 * (chaingen_runtime.h).
 *
 * The model is reached through `const chaingen_model *` (sizes and generated functions) and the
 * workspace through `const chaingen_workspace *` (a view: the scalars, the generated functions'
 * argument and work arrays, and two flat arrays of ints and doubles). Each entry point carves the
 * flat arrays into its named arrays once (carve(), in the order of the formula of
 * chaingen_workspace.h), into a local struct: the workspace itself holds no pointers.
 *
 * A package compiles this file into its own source (a unity build, see chaingen_runtime.h), and
 * should fix its model at compile time, its table a static const chaingen_model:
 *     #define CHAINGEN_LINKAGE static
 *     #include "chaingen_runtime.h"
 *     static const chaingen_model MODEL = { ... };
 *     #define CHAINGEN_FIXED_MODEL (&MODEL)
 *     #include "chaingen_runtime.c"
 * Every function then reads the model there rather than through its argument (which is not
 * checked), so the compiler sees the model's sizes and features as the constants they are: it
 * specialises the loops (the LU factorisation and solve, the arm solve) to the sizes and drops
 * the code of the features the model lacks, as it did in a package's own rendered solver.
 * Without it a step runs the same operations on the same numbers (the results are bitwise the
 * same) with some 5 to 15% more instructions around them.
 *
 * Plain C99: no allocation, no global mutable state, no variable-length arrays. Matrices are
 * dense and column-major. Units SI. */
#include <float.h>
#include <limits.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "chaingen_runtime.h"
#include "chaingen_lu.h"
#include "chaingen_arm_solve.h"

/* The model a function works with: its argument, or the package's fixed model (see above). */
#ifdef CHAINGEN_FIXED_MODEL
#define CG_MODEL(table) ((void)(table), CHAINGEN_FIXED_MODEL)
#else
#define CG_MODEL(table) (table)
#endif

/* Solutions of chained steps kept for the warm start: extrapolation of degree CG_HISTORY - 1. */
#define CG_HISTORY CHAINGEN_WARM_START_HISTORY
/* Newton with a Jacobian evaluated within the step is at the round-off floor when its updates
 * shrink by less than CG_FLOOR_RATE from one iterate to the next while the residual, relative to
 * its scale, is within CG_ROUNDOFF_RESIDUAL: the update is then round-off of an ill-conditioned
 * dF/dz (a cond of 1e8 turns a residual of 1e-14 into updates of 1e-12), and no further iterate
 * is better. The scale counts the Jacobian's terms only, and a residual entry sums many terms:
 * hence a thousand machine epsilons. (CHAINGEN_REFRESH_RATE: a kept Jacobian, simplified Newton or
 * Newton-chord, is evaluated anew when successive updates shrink by less than this.
 * CHAINGEN_SIMPLIFIED_MARGIN: a kept Jacobian stops with an estimated error this fraction of the
 * tolerance: it converges linearly, so without the margin its error would sit at the tolerance,
 * where full Newton's (quadratic) is far below it. CHAINGEN_CHORD_MARGIN: Newton-chord's margin;
 * it replaces full Newton, whose error at the stop is far below the tolerance, so it must stop
 * there too. CHAINGEN_MAX_SPLIT: halvings of a step that Newton fails on whole, at most
 * 2^MAX_SPLIT substeps.) */
#define CG_FLOOR_RATE 0.5
#define CG_ROUNDOFF_RESIDUAL (1024.0 * DBL_EPSILON)
/* Simplified Newton evaluates its Jacobian anew when its measured contraction would need more
 * than this many further updates to meet the tolerance: a Newton step converges quadratically,
 * in about as many. */
#define CG_REFRESH_ITERATIONS 2.0
/* Simplified Newton in a package whose own Newton is simplified (vi) gives up on a solve in which
 * this many Newton steps were followed at once by a Newton step with an update no smaller: the
 * ratio of successive Newton updates estimates h / 2, h = omega |dz| the Kantorovich quantity,
 * and h >= 2 lies outside the region where Newton's method is known to converge. From a first
 * guess far from the root it happens once, and Newton recovers; twice, in every solve of the
 * scaling chain of 50 links that did so, there was no root within reach (docs/model.md,
 * section 13). */
#define CG_NEWTON_GROWTHS 2
/* A model's Newton matrix (an approximation of dF/dz, spatial es) that had to be replaced within
 * a solve (it contracted poorly: a long step of a fast chain) is not tried again for this many
 * solves: they start with dF/dz itself, as the model's matrix would only cost them iterations. */
#define CG_EXACT_SOLVES 16
/* The adaptive steps' controller (see adaptive_interval). */
#define CG_SAFETY 0.9
#define CG_MIN_FACTOR 0.2
#define CG_MAX_FACTOR 5.0
#define CG_NEWTON_FACTOR 0.25
/* No entry's tolerance is below the round-off of its block (angles, rates): this many machine
 * epsilons of the block's largest magnitude, for the angles at least 1 rad (see
 * adaptive_interval). 32 eps = 7.1e-15 is below CHAINGEN_MIN_TOLERANCE, so an entry as large as
 * its block's largest is tested as before at any allowed rtol. */
#define CG_ESTIMATE_FLOOR (32.0 * DBL_EPSILON)
#define CG_TWO_PI 6.283185307179586

/* One entry point's view of the model and the workspace: the workspace's flat arrays carved into
 * the solver's named arrays (carve()). Arrays a model does not use are NULL. */
typedef struct {
    chaingen_workspace_scalars *s;
    const double **arg;
    double **res;
    long long int *iw;
    double *w;
    /* The step's constants y = step_constants(x0, u, q, dt) that the residual and the Newton
     * factors take (model->ny, ahead of CasADi's work array w in the workspace's). */
    double *y;
    /* Newton: the iterate, its update, the residual and its scale 1 + S_i. */
    double *z, *dz, *residual, *residual_scale;
    /* The Newton matrix: dense dF/dz (NZ x NZ) and its LU factors in jacobian; or es's factors
     * (chaingen_arm_solve.h): H's nonzeros, G_mu, G_c, the masses and maps A_k; what factorise()
     * derives from them; the reduced n x n matrix (in jacobian) and its factors; the scratch. */
    double *arm_factors, *arm_derived, *jacobian, *arm_scratch;
    int *pivot;
    /* The simulate loop's two states, a step's candidate x1, and the Newton state carried from
     * step to step (warm start): the state the last step produced and its solutions z. */
    double *state[2], *candidate, *previous_x1, *energy_x, *previous_z;
    /* The derived parameters q = Q(p), and the p they belong to. */
    double *q, *q_of;
    /* Mid-points of split steps (MAX_SPLIT x NX) and, for a held law (held_control), the
     * second halves' inputs (MAX_SPLIT x NU); the adaptive steps' states of one attempt (start,
     * one step, the two halves' middle and end). */
    double *split_state, *split_inputs, *adaptive_state;
    /* The sensitivity solve's right-hand sides (NZ x NCHAIN_SENS) and ds1/dz (NCHAIN x NZ). */
    double *sensitivity_rhs, *s1_z;
    /* The composed step: the states between its stages, the stages' warm starts (stage_z:
     * NSTAGE x HISTORY x NZ; stage_history, stage_choice), the end of the last composed step. */
    double *stage_state, *composed_x1, *stage_z;
    int *stage_history, *stage_choice;
    /* The stage's and the accumulated sensitivities [ds_ds ds_du ds_dp] (NCHAIN x NCHAIN_SENS),
     * and with chain_state the maps to joint space and a column of them. */
    double *stage_sensitivities, *composed_sensitivities;
    double *x0_s0, *s1_x1, *chain_column, *x0_p, *s1_p;
    /* Scratch: a step's segment margins (2 NSEGMENT), the constraint output (NCONSTRAINT + 1),
     * a posture's state (NX) and zero rates (N), the adaptive step's joint states (2N each), the
     * controller's phi, omega (N each) and held inputs (NU), a composed sensitivities' column. */
    double *margins, *constraint, *posture, *rest;
    double *joint_start, *joint_whole, *joint_ends;
    double *phi, *omega, *held, *column;
} cg_solver;

/* The next `size` entries of a carved array, or NULL (and none taken) when the model does not use
 * them. */
static double *cg_take(double **d, long size, int used)
{
    double *const taken = used ? *d : NULL;
    if (used) {
        *d += size;
    }
    return taken;
}

/* The workspace's arrays, carved from workspace->doubles and workspace->ints in the order and
 * sizes of CHAINGEN_WORKSPACE_DOUBLES and CHAINGEN_WORKSPACE_INTS (chaingen_workspace.h). Every
 * field is assigned once, NULL when unused: every entry point carves, and zeroing the struct
 * first (a memset of its ~60 pointers) cost a 3-link step 5-9% (issue 31's performance check). */
static void cg_carve(const chaingen_model *table, const chaingen_workspace *workspace, cg_solver *c)
{
    const chaingen_model *const model = CG_MODEL(table);
    const int n = model->n_joints, nx = model->nx, nz = model->nz;
    const int nchain = CHAINGEN_NCHAIN(n, nx, model->chain_state);
    const int nsens = CHAINGEN_NCHAIN_SENS(n, nx, model->nu, model->np, model->chain_state);
    const int staged = model->nstage > 0, arm = model->arm_nh > 0;
    const int sensitivities = model->sensitivities;
    const int chained = staged && sensitivities && model->chain_state;
    double *d = workspace->doubles;
    int *k = workspace->ints;
    c->s = workspace->scalars;
    c->arg = workspace->arg;
    c->res = workspace->res;
    c->iw = workspace->iw;
    c->y = model->ny > 0 ? workspace->w : NULL;
    c->w = workspace->w + model->ny;
    c->z = cg_take(&d, nz, 1);
    c->dz = cg_take(&d, nz, 1);
    c->residual = cg_take(&d, nz, 1);
    c->residual_scale = cg_take(&d, nz, 1);
    c->arm_factors = cg_take(&d, model->arm_nh + 9 * n, arm);
    c->arm_derived = cg_take(&d, 15 * n, arm);
    c->jacobian = cg_take(&d, arm ? n * n : nz * nz, 1);
    c->arm_scratch = cg_take(&d, 6 * n, arm);
    c->state[0] = cg_take(&d, nx, 1);
    c->state[1] = cg_take(&d, nx, 1);
    c->candidate = cg_take(&d, nx, 1);
    c->previous_x1 = cg_take(&d, nx, 1);
    c->energy_x = cg_take(&d, nx, 1);
    c->previous_z = cg_take(&d, CG_HISTORY * nz, 1);
    c->q = cg_take(&d, model->nq > 0 ? model->nq : 1, 1);
    c->q_of = cg_take(&d, model->np, 1);
    c->split_state = cg_take(&d, CHAINGEN_MAX_SPLIT * nx, 1);
    c->split_inputs = cg_take(&d, CHAINGEN_MAX_SPLIT * model->nu, 1);
    c->adaptive_state = cg_take(&d, 4 * nx, 1);
    c->sensitivity_rhs = cg_take(&d, nz * nsens, sensitivities);
    c->s1_z = cg_take(&d, nchain * nz, sensitivities);
    c->stage_state = cg_take(&d, 2 * nx, staged);
    c->composed_x1 = cg_take(&d, nx, staged);
    c->stage_z = cg_take(&d, model->nstage * CG_HISTORY * nz, staged);
    c->stage_sensitivities = cg_take(&d, nchain * nsens, staged && sensitivities);
    c->composed_sensitivities = cg_take(&d, nchain * nsens, staged && sensitivities);
    c->x0_s0 = cg_take(&d, nx * 2 * n, chained);
    c->s1_x1 = cg_take(&d, 2 * n * nx, chained);
    c->chain_column = cg_take(&d, nx, chained);
    c->x0_p = cg_take(&d, nx * model->np, chained);
    c->s1_p = cg_take(&d, 2 * n * model->np, chained);
    c->margins = cg_take(&d, 2 * model->nsegment, 1);
    c->constraint = cg_take(&d, model->nconstraint + 1, 1);
    c->posture = cg_take(&d, nx, 1);
    c->rest = cg_take(&d, n, 1);
    c->joint_start = cg_take(&d, 2 * n, 1);
    c->joint_whole = cg_take(&d, 2 * n, 1);
    c->joint_ends = cg_take(&d, 2 * n, 1);
    c->phi = cg_take(&d, n, 1);
    c->omega = cg_take(&d, n, 1);
    c->held = cg_take(&d, model->nu, 1);
    c->column = cg_take(&d, nchain, staged && sensitivities);
    c->pivot = k;
    k += nz;
    c->stage_history = k;
    k += model->nstage;
    c->stage_choice = k;
}

/* Whether the model and the workspace view can be used at all. */
static int cg_bad_view(const chaingen_model *table, const chaingen_workspace *workspace)
{
    const chaingen_model *const model = CG_MODEL(table);
    return !model || !workspace || !workspace->scalars || !workspace->arg || !workspace->res
           || !workspace->ints || !workspace->doubles;
}

/* The fixed ABI's sizes: nu and np must be the model's; u may be NULL only when nu is 0 (unless
 * u_optional: simulate_observed's zero torques), p only when np is 0. */
static int cg_bad_sizes(const chaingen_model *table, const double *u, int nu, int u_optional,
                        const double *p, int np)
{
    const chaingen_model *const model = CG_MODEL(table);
    return nu != model->nu || np != model->np || (!u && model->nu > 0 && !u_optional)
           || (!p && model->np > 0);
}

CHAINGEN_LINKAGE long chaingen_dimension(const chaingen_model *table, int which)
{
    const chaingen_model *const model = CG_MODEL(table);
    if (!model) {
        return -1;
    }
    switch (which) {
    case CHAINGEN_DIMENSION_N_JOINTS:
        return model->n_joints;
    case CHAINGEN_DIMENSION_NX:
        return model->nx;
    case CHAINGEN_DIMENSION_NZ:
        return model->nz;
    case CHAINGEN_DIMENSION_NU:
        return model->nu;
    case CHAINGEN_DIMENSION_NP:
        return model->np;
    case CHAINGEN_DIMENSION_NSAMPLE:
        return model->nsample;
    case CHAINGEN_DIMENSION_NCONSTRAINT:
        return model->nconstraint;
    case CHAINGEN_DIMENSION_ORDER:
        return model->order;
    case CHAINGEN_DIMENSION_NSTAGE:
        return model->nstage;
    case CHAINGEN_DIMENSION_SENSITIVITIES:
        return model->sensitivities ? 1 : 0;
    default:
        return -1;
    }
}

CHAINGEN_LINKAGE long chaingen_workspace_doubles(const chaingen_model *table)
{
    const chaingen_model *const model = CG_MODEL(table);
    if (!model) {
        return 0;
    }
    return CHAINGEN_WORKSPACE_DOUBLES((long)model->n_joints, (long)model->nx, (long)model->nz,
                                      (long)model->nu, (long)model->np, (long)model->nq,
                                      (long)model->nstage, (long)model->arm_nh,
                                      model->sensitivities, model->chain_state,
                                      (long)model->nsegment, (long)model->nconstraint);
}

CHAINGEN_LINKAGE long chaingen_workspace_ints(const chaingen_model *table)
{
    const chaingen_model *const model = CG_MODEL(table);
    if (!model) {
        return 0;
    }
    return CHAINGEN_WORKSPACE_INTS((long)model->nz, (long)model->nstage);
}

CHAINGEN_LINKAGE void chaingen_workspace_init(const chaingen_model *table,
                                              const chaingen_workspace *workspace)
{
    const chaingen_model *const model = CG_MODEL(table);
    if (!workspace) {
        return;
    }
    if (workspace->scalars) {
        memset(workspace->scalars, 0, sizeof *workspace->scalars);
    }
    if (model && workspace->ints) {
        memset(workspace->ints, 0, sizeof(int) * (size_t)chaingen_workspace_ints(model));
    }
    if (model && workspace->doubles) {
        memset(workspace->doubles, 0, sizeof(double) * (size_t)chaingen_workspace_doubles(model));
    }
}

CHAINGEN_LINKAGE void chaingen_default_options(const chaingen_model *table,
                                               chaingen_options *options)
{
    const chaingen_model *const model = CG_MODEL(table);
    if (!model || !options) {
        return;
    }
    *options = model->defaults;
}

/* Whether the n entries of v are all finite: the inputs a caller gives are checked with it. */
static int cg_all_finite(const double *v, int n)
{
    int i;
    for (i = 0; i < n; ++i) {
        if (!isfinite(v[i])) {
            return 0;
        }
    }
    return 1;
}

/* Evaluate a generated function: inputs and outputs by position (workspace arg and res), NULL
 * outputs skipped. A function the model lacks fails as an evaluation. */
static int cg_evaluate(chaingen_function function, const cg_solver *c)
{
    if (!function) {
        return CHAINGEN_EVALUATION_FAILED;
    }
    return function(c->arg, c->res, c->iw, c->w, 0) ? CHAINGEN_EVALUATION_FAILED : CHAINGEN_OK;
}

/* The derived parameters q = Q(p) in the workspace: the parts of the model that depend on the
 * parameters alone, evaluated here when p changes instead of in every evaluation of every step.
 * A new p also ends the Newton state carried from step to step (warm start, kept Jacobian): it
 * belongs to the old one. A p_i that is not finite or below its bound (model->p_lower,
 * p_inclusive: whether p_i may equal it; -DBL_MAX, inclusive: any finite value): nothing
 * changes, BAD_PARAMETER. */
static int cg_derive_parameters(const chaingen_model *table, const cg_solver *c, const double *p)
{
    const chaingen_model *const model = CG_MODEL(table);
    const int np = model->np;
    const double *arg[1];
    double *res[1];
    int i;
    if (c->s->q_valid && !memcmp(p, c->q_of, sizeof(double) * (size_t)np)) {
        return CHAINGEN_OK;
    }
    for (i = 0; i < np; ++i) {
        if (!isfinite(p[i])
            || (model->p_lower
                && !(model->p_inclusive && model->p_inclusive[i] ? p[i] >= model->p_lower[i]
                                                                  : p[i] > model->p_lower[i]))) {
            return CHAINGEN_BAD_PARAMETER;
        }
    }
    arg[0] = p;
    res[0] = c->q;
    c->s->history = 0;
    if (model->energy_check) {
        c->s->energy_valid = 0;
    }
    if (model->nstage > 0) {
        c->s->composed_valid = 0;
    }
    c->s->factors_valid = 0;
    c->s->q_valid = 0;
    if (!model->parameters || model->parameters(arg, res, c->iw, c->w, 0)) {
        return CHAINGEN_EVALUATION_FAILED;
    }
    memcpy(c->q_of, p, sizeof(double) * (size_t)np);
    c->s->q_valid = 1;
    return CHAINGEN_OK;
}

/* q = Q(p) derived as above; a model without parameters (np = 0) has nothing to derive. */
static int cg_derive(const chaingen_model *table, const cg_solver *c, const double *p)
{
    const chaingen_model *const model = CG_MODEL(table);
    return model->np > 0 ? cg_derive_parameters(model, c, p) : CHAINGEN_OK;
}

/* Whether every spring segment of the state x (finite) is long enough to start from: OK, or
 * SEGMENT_COLLAPSED where one is of (numerically) zero length and its direction undefined. A
 * start state's segments are measured as the scene reader measures the initial angles: each at
 * least ZERO_SEGMENT_RELATIVE_TOLERANCE of the geometry's size G long (G at the scene's own
 * numbers, as in the run's check); in margins (length / RUN_SEGMENT_RELATIVE_TOLERANCE G) that
 * is model->start_margin. A step checks its new state itself; this is for the states a caller
 * hands in (q derived). The length alone: a segment has no turn within one state (and a huge
 * finite one, whose squared length overflows, is long, not collapsed). */
static int cg_start_segments(const chaingen_model *table, const cg_solver *c, const double *x)
{
    const chaingen_model *const model = CG_MODEL(table);
    double *margins = c->margins;
    int i;
    c->arg[0] = x;
    c->arg[1] = x;
    if (model->np > 0) {
        c->arg[2] = c->q;
    }
    c->res[0] = margins;
    if (cg_evaluate(model->segment_margins, c)) {
        return CHAINGEN_EVALUATION_FAILED;
    }
    for (i = 0; i < model->nsegment; ++i) {
        if (!(margins[i] >= model->start_margin)) {
            return CHAINGEN_SEGMENT_COLLAPSED;
        }
    }
    return CHAINGEN_OK;
}

/* The state of posture phi at rest into x[NX], its segments checked (start_segments). */
static int cg_posture_state(const chaingen_model *table, const cg_solver *c, const double *phi,
                            double *x)
{
    const chaingen_model *const model = CG_MODEL(table);
    double *rest = c->rest;
    int i;
    for (i = 0; i < model->n_joints; ++i) {
        rest[i] = 0.0;
    }
    c->arg[0] = phi;
    c->arg[1] = rest;
    if (model->np > 0) {
        c->arg[2] = c->q;
    }
    c->res[0] = x;
    if (cg_evaluate(model->initial_state, c)) {
        return CHAINGEN_EVALUATION_FAILED;
    }
    return cg_all_finite(x, model->nx) ? cg_start_segments(model, c, x) : CHAINGEN_NONFINITE;
}

CHAINGEN_LINKAGE int chaingen_initial_state(const chaingen_model *table, const double *phi,
                                            const double *phidot, const double *p, int np,
                                            double *x, const chaingen_workspace *workspace)
{
    const chaingen_model *const model = CG_MODEL(table);
    cg_solver solver, *c = &solver;
    int status;
    if (cg_bad_view(model, workspace) || cg_bad_sizes(model, NULL, model->nu, 1, p, np)) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    if (!phi || !phidot || !x || !cg_all_finite(phi, model->n_joints)
        || !cg_all_finite(phidot, model->n_joints)) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    cg_carve(model, workspace, c);
    status = cg_derive(model, c, p);
    if (status != CHAINGEN_OK) {
        return status;
    }
    c->arg[0] = phi;
    c->arg[1] = phidot;
    if (model->np > 0) {
        c->arg[2] = c->q;
    }
    if (model->nsegment > 0) {
        /* Into the workspace first: a posture with a collapsed segment leaves x untouched. */
        double *state = c->posture;
        c->res[0] = state;
        status = cg_evaluate(model->initial_state, c);
        if (status == CHAINGEN_OK) {
            status = cg_all_finite(state, model->nx) ? cg_start_segments(model, c, state)
                                                     : CHAINGEN_NONFINITE;
        }
        if (status == CHAINGEN_OK) {
            memcpy(x, state, sizeof(double) * (size_t)model->nx);
        }
        return status;
    }
    c->res[0] = x;
    return cg_evaluate(model->initial_state, c);
}

/* Joint space and diagnostics of a state (the entry point outputs, on a carved workspace). */
static int cg_outputs(const chaingen_model *table, const cg_solver *c, const double *x,
                      const double *p, double *phi, double *omega, double *energy,
                      double *constraint_error)
{
    const chaingen_model *const model = CG_MODEL(table);
    double *constraint = c->constraint;
    double largest = 0.0;
    int i, status;
    if (!x || (!p && model->np > 0) || !cg_all_finite(x, model->nx)) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    status = cg_derive(model, c, p);
    if (status != CHAINGEN_OK) {
        return status;
    }
    c->arg[0] = x;
    if (model->np > 0) {
        c->arg[1] = c->q;
    }
    c->res[0] = phi;
    c->res[1] = omega;
    c->res[2] = energy;
    c->res[3] = constraint;
    status = cg_evaluate(model->outputs, c);
    for (i = 0; i < model->nconstraint; ++i) {
        if (!(fabs(constraint[i]) <= largest)) {
            largest = fabs(constraint[i]);
        }
    }
    if (constraint_error) {
        *constraint_error = largest;
    }
    return status;
}

CHAINGEN_LINKAGE int chaingen_outputs(const chaingen_model *table, const double *x, const double *p,
                                      int np, double *phi, double *omega, double *energy,
                                      double *constraint_error, const chaingen_workspace *workspace)
{
    const chaingen_model *const model = CG_MODEL(table);
    cg_solver solver;
    if (cg_bad_view(model, workspace) || cg_bad_sizes(model, NULL, model->nu, 1, p, np)) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    cg_carve(model, workspace, &solver);
    return cg_outputs(model, &solver, x, p, phi, omega, energy, constraint_error);
}

CHAINGEN_LINKAGE int chaingen_holding_torques(const chaingen_model *table, const double *phi,
                                              const double *p, int np, double *tau,
                                              const chaingen_workspace *workspace)
{
    const chaingen_model *const model = CG_MODEL(table);
    cg_solver solver, *c = &solver;
    int status;
    if (model && !model->holding_torques) {
        return CHAINGEN_UNAVAILABLE;
    }
    if (cg_bad_view(model, workspace) || cg_bad_sizes(model, NULL, model->nu, 1, p, np)) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    if (!phi || !tau || !cg_all_finite(phi, model->n_joints)) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    cg_carve(model, workspace, c);
    status = cg_derive(model, c, p);
    if (status != CHAINGEN_OK) {
        return status;
    }
    if (model->nsegment > 0) {
        /* A posture initial_state refuses (a segment of zero length, where dV/dphi is
         * undefined): SEGMENT_COLLAPSED. */
        status = cg_posture_state(model, c, phi, c->posture);
        if (status != CHAINGEN_OK) {
            return status;
        }
    }
    c->arg[0] = phi;
    if (model->np > 0) {
        c->arg[1] = c->q;
    }
    c->res[0] = tau;
    return cg_evaluate(model->holding_torques, c);
}

/* Point the generated step functions' inputs at (z, x0, [u], [q], dt, [y]): u when the model
 * has inputs, q = Q(p) (derived by the caller) when it has parameters, y the step's constants
 * (cg_step_constants, evaluated by the caller for this x0, u, q and dt) when it has them; a
 * function that does not take y reads the inputs before it. */
static void cg_step_arguments(const chaingen_model *table, const cg_solver *c, const double *z,
                              const double *x0, const double *u, const double *dt)
{
    const chaingen_model *const model = CG_MODEL(table);
    int k = 2;
    c->arg[0] = z;
    c->arg[1] = x0;
    if (model->nu > 0) {
        c->arg[k++] = u;
    }
    if (model->np > 0) {
        c->arg[k++] = c->q;
    }
    c->arg[k] = dt;
    if (model->ny > 0) {
        c->arg[k + 1] = c->y;
    }
}

/* The step's constants y in the workspace, for x0, u, dt and the derived q (cg_derive first):
 * every entry point evaluates them before the residual or the Newton factors at a new start,
 * Newton once a solve. */
static int cg_step_constants(const chaingen_model *table, const cg_solver *c, const double *x0,
                             const double *u, double dt)
{
    const chaingen_model *const model = CG_MODEL(table);
    int k = 1;
    if (model->ny == 0) {
        return CHAINGEN_OK;
    }
    c->arg[0] = x0;
    if (model->nu > 0) {
        c->arg[k++] = u;
    }
    if (model->np > 0) {
        c->arg[k++] = c->q;
    }
    c->arg[k] = &dt;
    c->res[0] = c->y;
    return cg_evaluate(model->step_constants, c);
}

/* The Newton matrix's factors in the workspace, as chaingen_arm_solve.h reads them (es's arm
 * solve: model->arm_nh > 0). */
static chaingen_arm_system cg_arm_system(const chaingen_model *table, const cg_solver *c)
{
    const chaingen_model *const model = CG_MODEL(table);
    chaingen_arm_system system;
    system.n = model->n_joints;
    system.nh = model->arm_nh;
    system.h_row = model->arm_h_row;
    system.h_col = model->arm_h_col;
    system.h = c->arm_factors;
    system.derived = c->arm_derived;
    system.reduced = c->jacobian;
    system.pivot = c->pivot;
    system.scratch = c->arm_scratch;
    return system;
}

/* F and the factors of a Newton matrix at z (arm solve): `factors` is the model's
 * newton_factors (dF/dz's) or chord_factors (the chord's); the factors go to the workspace. */
static int cg_newton_factors(const chaingen_model *table, const cg_solver *c,
                             chaingen_function factors, const double *z, const double *x0,
                             const double *u, double dt, double *residual)
{
    const chaingen_model *const model = CG_MODEL(table);
    cg_step_arguments(model, c, z, x0, u, &dt);
    c->res[0] = residual;
    c->res[1] = c->arm_factors;
    return cg_evaluate(factors, c);
}

/* Factorise the Newton matrix: with the arm solve, the reduced n x n system of
 * chaingen_arm_solve.h from the factors newton_factors left in the workspace; otherwise dF/dz in
 * the workspace's jacobian in place, dense LU with partial pivoting. Nonzero: singular. */
static int cg_factorise(const chaingen_model *table, const cg_solver *c)
{
    const chaingen_model *const model = CG_MODEL(table);
    if (model->arm_nh > 0) {
        const chaingen_arm_system system = cg_arm_system(model, c);
        return chaingen_arm_factor(&system);
    }
    return chaingen_lu_factor(model->nz, c->jacobian, c->pivot);
}

/* Solve dF/dz x = b in place of b, with the factors of factorise(). */
static void cg_solve_newton(const chaingen_model *table, const cg_solver *c, double *b)
{
    const chaingen_model *const model = CG_MODEL(table);
    if (model->arm_nh > 0) {
        const chaingen_arm_system system = cg_arm_system(model, c);
        chaingen_arm_solve(&system, b);
    } else {
        chaingen_lu_solve(model->nz, c->jacobian, c->pivot, b);
    }
}

/* The residual for Newton, whose steps may be negative (a stage of a composed step); with
 * `constants`, the step's constants evaluated first (Newton evaluates them once a solve). */
static int cg_evaluate_residual(const chaingen_model *table, const cg_solver *c, const double *z,
                                const double *x0, const double *u, const double *p, double dt,
                                double *residual, int constants)
{
    const chaingen_model *const model = CG_MODEL(table);
    int status;
    if (!z || !x0 || (!u && model->nu > 0) || (!p && model->np > 0) || !residual) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    status = cg_derive(model, c, p);
    if (status == CHAINGEN_OK && constants) {
        status = cg_step_constants(model, c, x0, u, dt);
    }
    if (status != CHAINGEN_OK) {
        return status;
    }
    cg_step_arguments(model, c, z, x0, u, &dt);
    c->res[0] = residual;
    return cg_evaluate(model->residual, c);
}

/* F and dF/dz at z (jacobian[i + j*NZ] = dF_i/dz_j). With the arm solve, dF/dz is formed from
 * its factors, which replace the workspace's: its kept factorisation is no more. */
static int cg_evaluate_residual_jacobian(const chaingen_model *table, const cg_solver *c,
                                         const double *z, const double *x0, const double *u,
                                         const double *p, double dt, double *residual,
                                         double *jacobian)
{
    const chaingen_model *const model = CG_MODEL(table);
    int status;
    if (!z || !x0 || (!u && model->nu > 0) || (!p && model->np > 0) || !residual || !jacobian) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    status = cg_derive(model, c, p);
    if (status == CHAINGEN_OK) {
        status = cg_step_constants(model, c, x0, u, dt);
    }
    if (status != CHAINGEN_OK) {
        return status;
    }
    if (model->arm_nh > 0) {
        c->s->factors_valid = 0;
        if (cg_newton_factors(model, c, model->newton_factors, z, x0, u, dt, residual)) {
            return CHAINGEN_EVALUATION_FAILED;
        }
        {
            const chaingen_arm_system system = cg_arm_system(model, c);
            chaingen_arm_jacobian(&system, jacobian);
        }
        return CHAINGEN_OK;
    }
    cg_step_arguments(model, c, z, x0, u, &dt);
    c->res[0] = residual;
    c->res[1] = jacobian;
    return cg_evaluate(model->residual_jacobian, c);
}

CHAINGEN_LINKAGE int chaingen_residual(const chaingen_model *table, const double *z,
                                       const double *x0, const double *u, int nu, const double *p,
                                       int np, double dt, double *residual,
                                       const chaingen_workspace *workspace)
{
    const chaingen_model *const model = CG_MODEL(table);
    cg_solver solver;
    if (cg_bad_view(model, workspace) || cg_bad_sizes(model, u, nu, 0, p, np)) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    if (!(dt > 0.0) || !isfinite(dt)) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    cg_carve(model, workspace, &solver);
    return cg_evaluate_residual(model, &solver, z, x0, u, p, dt, residual, 1);
}

CHAINGEN_LINKAGE int chaingen_residual_jacobian(const chaingen_model *table, const double *z,
                                                const double *x0, const double *u, int nu,
                                                const double *p, int np, double dt,
                                                double *residual, double *jacobian,
                                                const chaingen_workspace *workspace)
{
    const chaingen_model *const model = CG_MODEL(table);
    cg_solver solver;
    if (cg_bad_view(model, workspace) || cg_bad_sizes(model, u, nu, 0, p, np)) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    if (!(dt > 0.0) || !isfinite(dt)) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    cg_carve(model, workspace, &solver);
    return cg_evaluate_residual_jacobian(model, &solver, z, x0, u, p, dt, residual, jacobian);
}

/* The scheme's predictor from x0 into guess (it takes the derived q). */
static int cg_predict(const chaingen_model *table, const cg_solver *c, const double *x0, double dt,
                      double *guess)
{
    const chaingen_model *const model = CG_MODEL(table);
    c->arg[0] = x0;
    if (model->np > 0) {
        c->arg[1] = c->q;
        c->arg[2] = &dt;
    } else {
        c->arg[1] = &dt;
    }
    c->res[0] = guess;
    return cg_evaluate(model->predictor, c);
}

/* Entry i of the extrapolation of the last `points` solutions in previous_z (polynomial of
 * degree points - 1 through them, at the next step). */
static inline double cg_extrapolate(const chaingen_model *table, const cg_solver *c, int points, int i)
{
    const chaingen_model *const model = CG_MODEL(table);
    const double *previous = c->previous_z;
    const int nz = model->nz;
    switch (points) {
    case 1:
        return previous[i];
    case 2:
        return 2.0 * previous[i] - previous[nz + i];
    default:
        return 3.0 * (previous[i] - previous[nz + i]) + previous[2 * nz + i];
    }
}

/* The first Newton guess: the scheme's predictor from x0, or with `warm`, when this step
 * continues the workspace's previous one, the guess that would have been best for that step
 * (warm_choice, set by choose_warm_start): the predictor, or the extrapolation of the previous
 * solutions, from all of them (quadratic) or from fewer. */
static int cg_first_guess(const chaingen_model *table, const cg_solver *c, const double *x0,
                          double dt, int warm)
{
    const chaingen_model *const model = CG_MODEL(table);
    chaingen_workspace_scalars *s = c->s;
    int i;
    s->chained = warm && s->history > 0 && dt == s->previous_dt
                 && !memcmp(x0, c->previous_x1, sizeof(double) * (size_t)model->nx);
    if (s->chained && s->warm_choice != 1) {
        const int fewer = s->warm_choice - 1;   /* > 0: extrapolate from these */
        const int points = fewer > 0 && fewer < s->history ? fewer : s->history;
        for (i = 0; i < model->nz; ++i) {
            c->z[i] = cg_extrapolate(model, c, points, i);
        }
        return CHAINGEN_OK;
    }
    return cg_predict(model, c, x0, dt, c->z);
}

/* After a chained step converged to z: which first guess would have been closest, in the
 * weighted norm of Newton's update test? The scheme's predictor, or the extrapolation from the
 * last 1, 2 or 3 solutions. The next step starts from it. Quadratic extrapolation is best while a
 * step resolves the motion; where it does not (a long chain's fast tail at dt = 0.01 s),
 * extrapolation magnifies the step-to-step changes and a lower degree, or the predictor, is
 * closer. Costs one predictor evaluation. */
static int cg_choose_warm_start(const chaingen_model *table, const cg_solver *c, const double *x0,
                                double dt, const chaingen_options *options)
{
    const chaingen_model *const model = CG_MODEL(table);
    chaingen_workspace_scalars *s = c->s;
    double error[CG_HISTORY + 1] = {0.0};
    double *guess = c->dz;   /* free once Newton has converged */
    int d, i, best = 0;
    if (!s->chained || s->history < 1) {
        return CHAINGEN_OK;
    }
    if (cg_predict(model, c, x0, dt, guess)) {
        return CHAINGEN_EVALUATION_FAILED;
    }
    for (i = 0; i < model->nz; ++i) {
        const double weight = 1.0 / (options->update_atol
                                     + options->update_rtol * fabs(c->z[i]));
        for (d = 0; d <= s->history; ++d) {
            const double value = d == 0 ? guess[i] : cg_extrapolate(model, c, d, i);
            const double distance = fabs(value - c->z[i]) * weight;
            if (!(distance <= error[d])) {
                error[d] = distance;
            }
        }
    }
    for (d = 1; d <= s->history; ++d) {
        if (error[d] < error[best]) {
            best = d;
        }
    }
    s->warm_choice = best + 1;
    return CHAINGEN_OK;
}

/* F (with_jacobian: and dF/dz, factorised later, and the residual's scale at it) at z, for
 * Newton; with_jacobian 2: the model's Newton matrix in place of dF/dz where it has one (its
 * newton_matrix, or with the arm solve its chord_factors).
 * Returns nonzero when an evaluation failed. */
static int cg_newton_evaluate(const chaingen_model *table, const cg_solver *c, const double *x0,
                              const double *u, const double *p, double dt, int with_jacobian)
{
    const chaingen_model *const model = CG_MODEL(table);
    const int nz = model->nz;
    const double *z = c->z, *jacobian = c->jacobian;
    int i, j, evaluated;
    if (!with_jacobian) {
        return cg_evaluate_residual(model, c, z, x0, u, p, dt, c->residual, 0);
    }
    c->s->factors_valid = 0;   /* the factors' storage is overwritten */
    if (model->arm_nh > 0) {
        chaingen_arm_system system = cg_arm_system(model, c);
        /* with_jacobian 2: the chord's factors, where the model has them (an approximate H) */
        evaluated = cg_newton_factors(model, c,
                                      with_jacobian == 2 && model->chord_factors
                                          ? model->chord_factors : model->newton_factors,
                                      z, x0, u, dt, c->residual);
        /* The residual's scale at this Jacobian, 1 + sum_j |dF_i/dz_j| |z_j|, bounded by its
         * factors. */
        if (!evaluated) {
            chaingen_arm_scale(&system, z, c->residual_scale);
        }
        return evaluated;
    }
    if (model->newton_matrix && with_jacobian == 2) {
        /* The scheme's own Newton matrix, an approximation of dF/dz that is cheaper to
         * evaluate (spatial es); dF/dz itself stays for the sensitivities and the checks. */
        evaluated = cg_derive(model, c, p);
        if (!evaluated) {
            cg_step_arguments(model, c, z, x0, u, &dt);
            c->res[0] = c->residual;
            c->res[1] = c->jacobian;
            evaluated = cg_evaluate(model->newton_matrix, c);
        }
    } else {
        evaluated = cg_evaluate_residual_jacobian(model, c, z, x0, u, p, dt, c->residual,
                                                  c->jacobian);
    }
    /* The residual's scale at this Jacobian: 1 + sum_j |dF_i/dz_j| |z_j|. */
    for (i = 0; i < nz; ++i) {
        c->residual_scale[i] = 1.0;
    }
    for (j = 0; j < nz; ++j) {
        for (i = 0; i < nz; ++i) {
            c->residual_scale[i] += fabs(jacobian[i + j * nz]) * fabs(z[j]);
        }
    }
    return evaluated;
}

/* The residual's norm relative to its scale, max_i |F_i| / (1 + S_i); NaN when an entry of F is
 * not finite. */
static double cg_residual_norm(const chaingen_model *table, const cg_solver *c)
{
    const chaingen_model *const model = CG_MODEL(table);
    double norm = 0.0;
    int i;
    for (i = 0; i < model->nz; ++i) {
        const double scaled = fabs(c->residual[i]) / c->residual_scale[i];
        if (!isfinite(c->residual[i])) {
            return NAN;
        }
        if (scaled > norm) {
            norm = scaled;
        }
    }
    return norm;
}

/* Newton's method on F(z, x0, [u], [q], dt) = 0 from the first guess, full, simplified or chord
 * (see the options in the package header), with the linear solves of factorise() and
 * solve_newton(), at most options->max_iterations of them. Leaves z in the workspace.
 *
 * Simplified Newton (the Jacobian kept across steps) takes a Newton step wherever the kept
 * Jacobian contracts poorly: it evaluates the Jacobian at the iterate when the residual shrank
 * by less than CHAINGEN_REFRESH_RATE since the last iterate (before the solve: no update is
 * spent on a Jacobian that no longer fits), when the updates shrink by less than that, or when
 * they shrink so slowly that more than CG_REFRESH_ITERATIONS further updates would be needed
 * (a Newton step converges quadratically from there). A step starts with a Jacobian at its first
 * guess when the last solve had to replace one evaluated within it (refresh_first: the Jacobian
 * changes fast along the motion). In a package whose own Newton is simplified (vi) it gives up,
 * *diverged set, when a Newton step fails the monotonicity test: the next update, by the
 * Jacobian evaluated at the step's start, did not shrink (after a residual that did not shrink,
 * that Jacobian is kept for this test); or when CG_NEWTON_GROWTHS Newton steps were each
 * followed at once by a Newton step with an update no smaller (the residual shrank, if by less
 * than CHAINGEN_REFRESH_RATE, so the Jacobian was evaluated anew and the test above had no
 * update to compare). There is then no root within Newton's reach (on a long chain at
 * dt = 0.01 s, the root of a step ends in a fold at a shorter dt: vi's discrete
 * Legendre transform is no longer invertible), and the step is split at once. Full Newton,
 * Newton-chord and es's and midpoint's simplified Newton never give up early.
 *
 * Newton-chord evaluates the Jacobian at the first guess and again only when the updates shrink
 * by less than CHAINGEN_REFRESH_RATE; it stops at CHAINGEN_CHORD_MARGIN. Kept across chained
 * steps (CHAINGEN_JACOBIAN_CHORD_ACROSS_STEPS, es's default), a step that continues the last
 * (the same dt, its start the last end) starts with the last step's Jacobian when the last
 * step had to replace the one of its first guess (refresh_first clear): there the first guess
 * is far from the root, and its Jacobian serves the chord no better than the last one. */
static int cg_newton(const chaingen_model *table, const cg_solver *c, const double *x0,
                     const double *u, const double *p, double dt, const chaingen_options *options,
                     int warm, int *iterations, int *diverged, int *cold)
{
    const chaingen_model *const model = CG_MODEL(table);
    chaingen_workspace_scalars *s = c->s;
    const int nz = model->nz;
    const int simplified = options->reuse_jacobian == CHAINGEN_JACOBIAN_ACROSS_STEPS;
    const int chord = options->reuse_jacobian == CHAINGEN_JACOBIAN_PER_STEP
                      || options->reuse_jacobian == CHAINGEN_JACOBIAN_CHORD_ACROSS_STEPS;
    /* Only the scheme whose own Newton is simplified (vi) gives up early: es and midpoint keep
     * their ladder under every option. */
    const int gives_up = simplified
                         && model->defaults.reuse_jacobian == CHAINGEN_JACOBIAN_ACROSS_STEPS;
    double *z, *dz, *residual;
    double previous_update = -1.0;   /* update norm of the previous iteration, < 0: none */
    double previous_residual = -1.0; /* its residual norm */
    int i, iteration = 0, status, fresh = 0;   /* fresh: dF/dz evaluated within this call */
    int evaluated_at = 0;   /* the iteration at whose iterate dF/dz was last evaluated (0: none) */
    int evaluations = 0;    /* of dF/dz within this call */
    int refreshed = 0;      /* dF/dz evaluated at an iterate after the first guess */
    double newton_update = -1.0;   /* the last iterate's update when it was a Newton step */
    int growths = 0;        /* Newton steps followed at once by one with an update no smaller */
    /* The model's Newton matrix (an approximation of dF/dz, spatial es) may be this solve's
     * first (chord, and it did not fail lately), and was. */
    const int approximate = chord && model->newton_matrix && s->exact_first == 0;
    /* The chord's every Newton matrix is of the model's chord factors, where it has them
     * (planar es with the exact gradient: H of the springs' quadrature alone, without its
     * correction, whose derivative is of the quadrature's error; docs/model.md 18). A chord
     * that fails climbs the ladder to full Newton, whose matrices are dF/dz. */
    const int chord_matrix = chord && model->chord_factors;
    int approximated = 0;
    z = c->z;
    dz = c->dz;
    residual = c->residual;
    *diverged = 0;
    *cold = 0;
    status = cg_first_guess(model, c, x0, dt, warm);
    /* The step's constants, once for every iterate of this solve. */
    if (status == CHAINGEN_OK) {
        status = cg_derive(model, c, p);
    }
    if (status == CHAINGEN_OK) {
        status = cg_step_constants(model, c, x0, u, dt);
    }
    /* The Jacobian kept from the last solve: simplified Newton's, unless dt changed or the last
     * solve replaced one within it; the chord's across steps, when this step continues the last
     * (chained: its start is the last end, the same dt). */
    if (simplified ? s->factors_dt != dt || s->refresh_first
                   : options->reuse_jacobian != CHAINGEN_JACOBIAN_CHORD_ACROSS_STEPS
                         || !s->chained || s->factors_dt != dt || s->refresh_first) {
        s->factors_valid = 0;
    }
    if (status == CHAINGEN_OK) {
        status = CHAINGEN_NOT_CONVERGED;
    }
    while (status == CHAINGEN_NOT_CONVERGED && iteration < options->max_iterations) {
        double residual_norm, update_norm = 0.0;
        int here = !s->factors_valid;   /* dF/dz evaluated at this iterate */
        ++iteration;
        if (iteration == 1) {
            /* The first guess is the predictor and dF/dz is evaluated there: a retry from the
             * predictor with a fresh Jacobian would repeat this solve. */
            *cold = here && !(s->chained && s->warm_choice != 1);
        }
        /* The model's Newton matrix (an approximation of dF/dz, spatial es) for the chord's
         * first matrix of a step; dF/dz itself for full Newton and wherever that matrix had to
         * be replaced within the step (it contracted poorly: a long step of a fast chain). */
        if (here && evaluations == 0) {
            approximated = approximate;
        }
        if (cg_newton_evaluate(model, c, x0, u, p, dt,
                               here && (chord_matrix || (evaluations == 0 && approximate))
                                   ? 2 : here)) {
            status = CHAINGEN_EVALUATION_FAILED;
            break;
        }
        residual_norm = cg_residual_norm(model, c);
        if (simplified && previous_residual > 0.0 && residual_norm > options->residual_tol
            && !isnan(residual_norm)) {
            if (evaluated_at == iteration - 1 && residual_norm >= previous_residual) {
                /* The Newton step from the previous iterate did not reduce the residual. The
                 * Jacobian it was taken with stays for this update, whose size tells (the
                 * residual's norm is not affine invariant; the update is): the step diverged
                 * when it does not shrink, tested after the solve. */
            } else if (!here && residual_norm > CHAINGEN_REFRESH_RATE * previous_residual) {
                /* The kept Jacobian reduced the residual too little: a Newton step from here. */
                here = 1;
                if (cg_newton_evaluate(model, c, x0, u, p, dt, 1)) {
                    status = CHAINGEN_EVALUATION_FAILED;
                    break;
                }
                residual_norm = cg_residual_norm(model, c);
            }
        }
        if (isnan(residual_norm)) {
            status = CHAINGEN_NONFINITE;
            break;
        }
        for (i = 0; i < nz; ++i) {
            dz[i] = -residual[i];
        }
        if (here) {
            if (cg_factorise(model, c)) {
                s->factors_valid = 0;
                status = CHAINGEN_SINGULAR_JACOBIAN;
                break;
            }
            s->factors_valid = 1;
            s->factors_dt = dt;
            fresh = 1;
            refreshed |= iteration > 1;
            evaluated_at = iteration;
            ++evaluations;
            if (options->reuse_jacobian != CHAINGEN_JACOBIAN_EVERY_ITERATE) {
                /* A new kept Jacobian: its contraction is measured afresh. (Full Newton has a
                 * new one every iterate and compares successive updates for the floor.) */
                previous_update = -1.0;
            }
        }
        cg_solve_newton(model, c, dz);
        for (i = 0; i < nz; ++i) {
            double ratio = fabs(dz[i]) / (options->update_atol + options->update_rtol * fabs(z[i]));
            if (!(ratio <= update_norm)) {
                update_norm = ratio;
            }
            z[i] += dz[i];
        }
        if (gives_up) {
            if (here && newton_update > 0.0 && update_norm >= newton_update) {
                ++growths;
            }
            newton_update = here ? update_norm : -1.0;
        }
        if (!isfinite(update_norm)) {
            status = CHAINGEN_NONFINITE;
        } else if (options->reuse_jacobian == CHAINGEN_JACOBIAN_EVERY_ITERATE) {
            /* Converged; or at the round-off floor: the update stopped shrinking (quadratic
             * convergence would have shrunk it by orders) while the residual is round-off of
             * its scale or stopped shrinking too, so the update is round-off of an
             * ill-conditioned dF/dz, and no further iterate is better. The residual's scale
             * counts the Jacobian's terms only; where other terms dominate (vi's momenta on a
             * long chain), its round-off lies above CG_ROUNDOFF_RESIDUAL and only the second
             * test sees it. A double root's linear convergence halves the update but quarters
             * the residual, so it is not taken for the floor. */
            int floor = previous_update > 0.0 && update_norm >= CG_FLOOR_RATE * previous_update
                        && (residual_norm <= CG_ROUNDOFF_RESIDUAL
                            || residual_norm >= CG_FLOOR_RATE * previous_residual);
            s->factors_valid = 0;
            if (residual_norm <= options->residual_tol && (update_norm <= 1.0 || floor)) {
                status = CHAINGEN_OK;
            }
            previous_update = update_norm;
            previous_residual = residual_norm;
        } else {
            /* With contraction rate theta the new iterate's error is at most theta / (1 - theta)
             * times the update. The rate is measured within this step only (a rate carried
             * over from earlier steps would go stale with the Jacobian, unnoticed); before
             * it is known, the update itself must be within tolerance, as for full Newton
             * (the error is then below it while theta <= 1/2). */
            int measured = previous_update > 0.0;
            double rate = measured ? update_norm / previous_update : 1.0;
            double margin = chord ? CHAINGEN_CHORD_MARGIN : CHAINGEN_SIMPLIFIED_MARGIN;
            int contracted = measured ? rate < 1.0 && rate / (1.0 - rate) * update_norm <= margin
                                      : update_norm <= margin;
            /* A Jacobian evaluated within this step that no longer contracts an update already
             * within tolerance: the iterate is at the round-off floor, where the margin cannot
             * be met. */
            int floor = measured && fresh
                        && ((rate > CHAINGEN_REFRESH_RATE && update_norm <= 1.0)
                            || (rate >= CG_FLOOR_RATE && residual_norm <= CG_ROUNDOFF_RESIDUAL));
            if (residual_norm <= options->residual_tol && (contracted || floor)) {
                status = CHAINGEN_OK;
            } else if (gives_up && ((measured && evaluated_at == iteration - 1 && rate >= 1.0)
                                    || growths >= CG_NEWTON_GROWTHS)) {
                /* The Newton step from the previous iterate failed the monotonicity test:
                 * the update by the Jacobian evaluated there did not shrink; or Newton steps
                 * kept growing (h >= 2 each time: CG_NEWTON_GROWTHS). */
                *diverged = 1;
                break;
            } else if (measured
                       && (rate > CHAINGEN_REFRESH_RATE
                           || (simplified
                               && log(margin * (1.0 - rate) / (rate * update_norm))
                                      < CG_REFRESH_ITERATIONS * log(rate)))) {
                s->factors_valid = 0;
            }
            previous_update = update_norm;
            previous_residual = residual_norm;
        }
    }
    if (model->newton_matrix && chord) {
        if (approximated && refreshed) {
            s->exact_first = CG_EXACT_SOLVES;
        } else if (s->exact_first > 0) {
            --s->exact_first;
        }
    }
    if (simplified) {
        s->refresh_first = evaluations > 1;
    } else if (options->reuse_jacobian == CHAINGEN_JACOBIAN_CHORD_ACROSS_STEPS) {
        /* The chord's Jacobian goes into the next step only when the one of this step's first
         * guess had to be replaced within it: a guess far from the root (a long chain's fast
         * tail) has a Jacobian no better than the last step's. From a guess near the root, a
         * fresh Jacobian there lands at round-off in one update. */
        s->refresh_first = !refreshed;
    }
    if (status == CHAINGEN_OK) {
        status = cg_choose_warm_start(model, c, x0, dt, options);
    }
    *iterations = iteration;
    return status;
}

/* Newton from the first guess; a warm start that fails is retried once from the scheme's
 * predictor with a fresh Jacobian (an extrapolated guess can be poor where the motion changes
 * abruptly; not when the first solve was that one already), and a kept Jacobian that fails is replaced by full Newton from the predictor
 * (unless simplified Newton gave up on a diverging Newton step, newton()): a step does at most
 * 3 max_iterations linear solves. options NULL: the model's defaults. */
static int cg_solve_step(const chaingen_model *table, const cg_solver *c, const double *x0,
                         const double *u, const double *p, double dt,
                         const chaingen_options *options, int *iterations)
{
    const chaingen_model *const model = CG_MODEL(table);
    chaingen_options defaults;
    int status, spent = 0, retried = 0, diverged = 0, cold = 0;
    if (!x0 || (!u && model->nu > 0) || (!p && model->np > 0) || !(dt != 0.0) || !isfinite(dt)) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    if (!options) {
        defaults = model->defaults;
        options = &defaults;
    }
    if (options->reuse_jacobian < CHAINGEN_JACOBIAN_EVERY_ITERATE
        || options->reuse_jacobian > CHAINGEN_JACOBIAN_CHORD_ACROSS_STEPS
        || !(options->energy_tol >= 0.0)) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    status = cg_newton(model, c, x0, u, p, dt, options, options->warm_start, &spent, &diverged,
                       &cold);
    /* A continuation step whose first solve started from the predictor with a Jacobian there
     * is not retried: the retry would repeat it, iterate for iterate. */
    if (status != CHAINGEN_OK && c->s->chained && !cold) {
        c->s->factors_valid = 0;
        status = cg_newton(model, c, x0, u, p, dt, options, 0, &retried, &diverged, &cold);
        spent += retried;
    }
    /* Simplified Newton that diverged took Newton steps already (newton()): full Newton from
     * the predictor would only repeat them. */
    if (status != CHAINGEN_OK && status != CHAINGEN_EVALUATION_FAILED && !diverged
        && options->reuse_jacobian != CHAINGEN_JACOBIAN_EVERY_ITERATE) {
        chaingen_options full = *options;
        full.reuse_jacobian = CHAINGEN_JACOBIAN_EVERY_ITERATE;
        c->s->factors_valid = 0;
        status = cg_newton(model, c, x0, u, p, dt, &full, 0, &retried, &diverged, &cold);
        spent += retried;
        if (status == CHAINGEN_OK) {
            ++c->s->step_fallbacks;
        }
    }
    if (iterations) {
        *iterations = spent;
    }
    return status;
}

/* (H, T) of a state, for the energy check of finish_step. */
static int cg_state_energies(const chaingen_model *table, const cg_solver *c, const double *x,
                             double *energies)
{
    const chaingen_model *const model = CG_MODEL(table);
    c->arg[0] = x;
    if (model->np > 0) {
        c->arg[1] = c->q;
    }
    c->res[0] = energies;
    return cg_evaluate(model->energy_terms, c);
}

/* x1 (and the energy flows, when the model reports them) from the converged z in the workspace.
 * The candidate is checked (finite; with spring segments, no segment collapsed; with the energy
 * check, the energy balance kept within energy_tol) before it is copied out: a failed step
 * leaves x1 untouched. */
static int cg_finish_step(const chaingen_model *table, const cg_solver *c, const double *x0,
                          const double *u, double dt, double *x1, double *flows,
                          const chaingen_options *options)
{
    const chaingen_model *const model = CG_MODEL(table);
    chaingen_workspace_scalars *s = c->s;
    const int nx = model->nx, nz = model->nz;
    double *candidate = c->candidate;
    double step_flows[2];
    int i, status;
    cg_step_arguments(model, c, c->z, x0, u, &dt);
    c->res[0] = candidate;
    if (model->flows) {
        c->res[1] = step_flows;
    }
    status = cg_evaluate(model->next_state, c);
    if (status != CHAINGEN_OK) {
        return status;
    }
    for (i = 0; i < nx; ++i) {
        if (!isfinite(candidate[i])) {
            return CHAINGEN_NONFINITE;
        }
    }
    if (model->nsegment > 0) {
        /* Every spring segment must keep a length above its tolerance, and must not pass
         * through zero length within the step: its direction turns by less than 90 degrees. */
        double *margins = c->margins;
        c->arg[0] = x0;
        c->arg[1] = candidate;
        if (model->np > 0) {
            c->arg[2] = c->q;
        }
        c->res[0] = margins;
        if (cg_evaluate(model->segment_margins, c)) {
            return CHAINGEN_EVALUATION_FAILED;
        }
        for (i = 0; i < model->nsegment; ++i) {
            if (!(margins[i] >= 1.0) || !(margins[model->nsegment + i] > 0.0)) {
                return CHAINGEN_SEGMENT_COLLAPSED;
            }
        }
    }
    if (model->energy_check) {
        /* The scheme keeps the energy balance H_1 - H_0 = W - D only up to its error, small
         * against the kinetic energy at the step's ends; a root that misses it by energy_tol
         * (T_0 + T_1) or more is spurious: Newton converged to another solution of a step too
         * long for the motion (docs/model.md, section 13). Within round-off it passes (a chain
         * held still has T = 0): of H's terms, whose magnitudes S sums (a controlled loop's
         * H_d cancels joules of them to nothing at its target), and of the flows. The
         * energies at x0 are the last accepted step's when it ended there. options NULL: the
         * model's default. */
        const double tolerance = options ? options->energy_tol : model->defaults.energy_tol;
        double start[3], end[3], balance, scale;
        if (tolerance > 0.0) {
            if (s->energy_valid && !memcmp(x0, c->energy_x, sizeof(double) * (size_t)nx)) {
                memcpy(start, s->energy_ends, sizeof(start));
            } else if (cg_state_energies(model, c, x0, start)) {
                return CHAINGEN_EVALUATION_FAILED;
            }
            if (cg_state_energies(model, c, candidate, end)) {
                return CHAINGEN_EVALUATION_FAILED;
            }
            scale = start[2] + end[2];
            if (model->flows) {
                balance = end[0] - start[0] - (step_flows[0] - step_flows[1]);
                scale += fabs(step_flows[0]) + fabs(step_flows[1]);
            } else {
                balance = end[0] - start[0];
            }
            if (!(fabs(balance) <= tolerance * (start[1] + end[1])
                                   + CG_ROUNDOFF_RESIDUAL * scale)) {
                return CHAINGEN_ENERGY_JUMP;
            }
            memcpy(c->energy_x, candidate, sizeof(double) * (size_t)nx);
            memcpy(s->energy_ends, end, sizeof(end));
            s->energy_valid = 1;
        }
    }
    memcpy(x1, candidate, sizeof(double) * (size_t)nx);
    /* Remember the solution for a warm start of the next step. */
    if (s->chained && s->history > 0) {
        memmove(c->previous_z + nz, c->previous_z, sizeof(double) * (size_t)nz * (CG_HISTORY - 1));
        if (s->history < CG_HISTORY) {
            ++s->history;
        }
    } else {
        /* A new chain (another trajectory, or another dt): the old history is gone, and with it
         * the choice measured on it; the next step chooses as after workspace_init. */
        s->history = 1;
        s->warm_choice = 0;
    }
    memcpy(c->previous_z, c->z, sizeof(double) * (size_t)nz);
    memcpy(c->previous_x1, x1, sizeof(double) * (size_t)nx);
    s->previous_dt = dt;
    if (model->flows && flows) {
        flows[0] = step_flows[0];
        flows[1] = step_flows[1];
    }
    return CHAINGEN_OK;
}

/* Whether a step that failed with `status` may pass when shorter: Newton failed on it, or its
 * solution was not finite, turned a spring segment through 90 degrees, or jumped in energy. (A
 * bad argument or a failed evaluation fails at any length.) */
static int cg_shorter_may_pass(const chaingen_model *table, int status)
{
    const chaingen_model *const model = CG_MODEL(table);
    return status == CHAINGEN_NOT_CONVERGED || status == CHAINGEN_SINGULAR_JACOBIAN
           || status == CHAINGEN_NONFINITE
           || (model->nsegment > 0 && status == CHAINGEN_SEGMENT_COLLAPSED)
           || (model->energy_check && status == CHAINGEN_ENERGY_JUMP);
}

/* The torques a held law's step applies, applied_torques at x0 with inputs u: u plus the law
 * of x0 (held_control: the law reads the step's start alone, not z nor dt), into tau. z is
 * given as zeros (c->dz, free between solves). */
static int cg_held_torques(const chaingen_model *table, const cg_solver *c, const double *x0,
                           const double *u, double dt, double *tau)
{
    const chaingen_model *const model = CG_MODEL(table);
    int status;
    memset(c->dz, 0, sizeof(double) * (size_t)model->nz);
    cg_step_arguments(model, c, c->dz, x0, u, &dt);
    c->res[0] = tau;
    status = cg_evaluate(model->applied_torques, c);
    if (status == CHAINGEN_OK && !cg_all_finite(tau, model->nu)) {
        status = CHAINGEN_NONFINITE;
    }
    return status;
}

/* One step, climbing the ladder of solve_step; when Newton fails on the whole step, or its
 * solution fails the segment test (a spurious root of a step too long for the motion turns a
 * segment through 90 degrees; a segment that really collapses fails every half too), or the
 * energy check (a spurious root that jumps in energy), two half steps, each climbing the same
 * ladder, at most MAX_SPLIT halvings deep. "es" conserves energy on any sequence of steps: the
 * halves keep its energy balance. The energy flows are the halves' sum; iterations counts every
 * linear solve.
 *
 * A held law (held_control: the torque u + law(x0) of the step's start, held over the step)
 * keeps the whole step's torque in its halves: the second half, which would sample the law at
 * its own start, the middle, takes the inputs u + law(x0) - law(middle) instead of u, so that
 * its torque is the whole step's (to round-off), and so on in every deeper half. Its flows'
 * input work then counts that difference's work too (it is the work of the torque the half
 * applies beyond the law it samples). */
static int cg_advance(const chaingen_model *table, const cg_solver *c, const double *x0,
                      const double *u, const double *p, double dt, double *x1, double *flows,
                      const chaingen_options *options, int *iterations, int depth)
{
    const chaingen_model *const model = CG_MODEL(table);
    int status, spent = 0;
    status = cg_solve_step(model, c, x0, u, p, dt, options, &spent);
    if (status == CHAINGEN_OK) {
        status = cg_finish_step(model, c, x0, u, dt, x1, flows, options);
    }
    *iterations += spent;
    if (cg_shorter_may_pass(model, status) && depth < CHAINGEN_MAX_SPLIT) {
        double *middle = c->split_state + depth * model->nx;
        double halves[2][2] = {{0.0, 0.0}, {0.0, 0.0}};
        const int held = model->held_control && model->nu > 0 && model->applied_torques;
        double *second = held ? c->split_inputs + depth * model->nu : NULL;
        const double *second_u = u;
        ++c->s->step_splits;
        if (held) {
            /* The whole step's torque, before the first half (whose solves reuse dz). */
            status = cg_held_torques(model, c, x0, u, dt, second);
            if (status != CHAINGEN_OK) {
                return status;
            }
        }
        status = cg_advance(model, c, x0, u, p, 0.5 * dt, middle, halves[0], options, iterations,
                            depth + 1);
        if (status == CHAINGEN_OK && held) {
            int i;
            double *sampled = c->rest;   /* N >= NU entries of scratch */
            status = cg_held_torques(model, c, middle, u, dt, sampled);
            for (i = 0; status == CHAINGEN_OK && i < model->nu; ++i) {
                second[i] = u[i] + (second[i] - sampled[i]);
            }
            second_u = second;
        }
        if (status == CHAINGEN_OK) {
            status = cg_advance(model, c, middle, second_u, p, 0.5 * dt, x1, halves[1], options,
                                iterations, depth + 1);
        }
        if (model->flows && status == CHAINGEN_OK && flows) {
            flows[0] = halves[0][0] + halves[1][0];
            flows[1] = halves[0][1] + halves[1][1];
        }
    }
    return status;
}

/* One step of the model's order, composed (model->nstage > 0): the scheme's step (with its
 * ladder, advance, splitting from `depth`) at dt * stages[s] for each stage in turn, fractions of
 * dt that sum to 1 (one negative: a step back in time). x1 is written by the last stage only: on
 * failure it is untouched. The energy flows are the stages' sum.
 *
 * The warm start works stage by stage: when this step continues the previous composed step (x0
 * bitwise its x1, the same dt), stage s starts from the extrapolation of stage s's own solutions
 * in the previous steps, which lie one step apart as a plain step's do. (A stage's neighbours
 * have other lengths, and extrapolating across them costs Newton iterations.) Otherwise a
 * stage continues the previous stage where the two have equal length. */
static int cg_compose(const chaingen_model *table, const cg_solver *c, const double *x0,
                      const double *u, const double *p, double dt, double *x1, double *flows,
                      const chaingen_options *options, int *iterations, int depth)
{
    const chaingen_model *const model = CG_MODEL(table);
    chaingen_workspace_scalars *ws = c->s;
    const int nx = model->nx;
    const size_t record = sizeof(double) * CG_HISTORY * (size_t)model->nz;
    const double *from = x0;
    double stage_flows[2] = {0.0, 0.0}, total[2] = {0.0, 0.0};
    const int continues = ws->composed_valid && dt == ws->composed_dt
                          && !memcmp(x0, c->composed_x1, sizeof(double) * (size_t)nx);
    int s, status = CHAINGEN_OK;
    ws->composed_valid = 0;
    for (s = 0; s < model->nstage && status == CHAINGEN_OK; ++s) {
        double *to = s == model->nstage - 1 ? x1 : c->stage_state + (s % 2) * nx;
        double *stage_z = c->stage_z + (size_t)s * CG_HISTORY * model->nz;
        const double stage_dt = model->stages[s] * dt;
        const int own = continues && c->stage_history[s] > 0;
        if (own) {
            memcpy(c->previous_z, stage_z, record);
            ws->history = c->stage_history[s];
            ws->warm_choice = c->stage_choice[s];
            memcpy(c->previous_x1, from, sizeof(double) * (size_t)nx);
            ws->previous_dt = stage_dt;
        }
        status = cg_advance(model, c, from, u, p, stage_dt, to, stage_flows, options, iterations,
                            depth);
        /* Keep the stage's record unless the stage was split (its last solve was shorter); a
         * record that did not start from the stage's own holds only this solution. */
        c->stage_history[s] = 0;
        if (status == CHAINGEN_OK && ws->previous_dt == stage_dt) {
            memcpy(stage_z, c->previous_z, record);
            c->stage_history[s] = own ? ws->history : 1;
            c->stage_choice[s] = ws->warm_choice;
        }
        if (model->flows && status == CHAINGEN_OK) {
            total[0] += stage_flows[0];
            total[1] += stage_flows[1];
        }
        from = to;
    }
    if (status == CHAINGEN_OK) {
        memcpy(c->composed_x1, x1, sizeof(double) * (size_t)nx);
        ws->composed_dt = dt;
        ws->composed_valid = 1;
    }
    if (model->flows && status == CHAINGEN_OK && flows) {
        flows[0] = total[0];
        flows[1] = total[1];
    }
    return status;
}

/* One step of the model's order: the composed step, or the scheme's step alone. */
static int cg_take_step(const chaingen_model *table, const cg_solver *c, const double *x0,
                        const double *u, const double *p, double dt, double *x1, double *flows,
                        const chaingen_options *options, int *iterations, int depth)
{
    const chaingen_model *const model = CG_MODEL(table);
    if (model->nstage > 0) {
        return cg_compose(model, c, x0, u, p, dt, x1, flows, options, iterations, depth);
    }
    return cg_advance(model, c, x0, u, p, dt, x1, flows, options, iterations, depth);
}

/* What step() and control_torques() do before a step: check the arguments (BAD_ARGUMENT),
 * carve the workspace, reset the step's counters, derive the parameters' quantities and check
 * the start state's segments (a run checks its start once: each later step starts where the one
 * before ended, checked as its x1). A NaN or Inf in x0 is left to the step (Newton fails on it). */
/* A NaN or Inf in the start state x0 or the inputs u: BAD_ARGUMENT before any work, in every
 * entry point that takes a step (not NONFINITE after Newton has spent its iterations on it). */
static int cg_bad_values(const chaingen_model *model, const double *x0, const double *u)
{
    return (x0 && !cg_all_finite(x0, model->nx)) || (u && !cg_all_finite(u, model->nu));
}

/* Options an entry point of one fixed step (step, step_sensitivities, control_torques) refuses:
 * rtol or atol other than 0. Adaptive steps are simulate's; these entry points take the dt they
 * are given, and would otherwise take it without a word that the tolerances went unused. */
static int cg_adaptive_options(const chaingen_options *options)
{
    return options && !(options->rtol == 0.0 && options->atol == 0.0);
}

static int cg_begin_step(const chaingen_model *model, const chaingen_workspace *workspace,
                         cg_solver *c, const double *x0, const double *u, int nu,
                         const double *p, int np, double dt)
{
    int status;
    if (cg_bad_view(model, workspace) || cg_bad_sizes(model, u, nu, 0, p, np)) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    if (!(dt > 0.0) || !isfinite(dt) || cg_bad_values(model, x0, u)) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    cg_carve(model, workspace, c);
    c->s->step_fallbacks = 0;
    c->s->step_splits = 0;
    status = cg_derive(model, c, p);
    if (status != CHAINGEN_OK) {
        return status;
    }
    if (model->nsegment > 0 && x0) {   /* finite: cg_bad_values above */
        return cg_start_segments(model, c, x0);
    }
    return CHAINGEN_OK;
}

CHAINGEN_LINKAGE int chaingen_step(const chaingen_model *table, const double *x0, const double *u,
                                   int nu, const double *p, int np, double dt, double *x1,
                                   double *flows, const chaingen_options *options,
                                   const chaingen_workspace *workspace, int *iterations)
{
    const chaingen_model *const model = CG_MODEL(table);
    cg_solver solver, *c = &solver;
    int spent = 0, status;
    if (!x1 || cg_adaptive_options(options)) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    status = cg_begin_step(model, workspace, c, x0, u, nu, p, np, dt);
    if (status != CHAINGEN_OK) {
        return status;
    }
    status = cg_take_step(model, c, x0, u, p, dt, x1, flows, options, &spent, 0);
    if (iterations) {
        *iterations = spent;
    }
    return status;
}

/* step()'s step from x0 (the same checks, warm start, Newton and rungs of the ladder within the
 * whole step: a warm start retried from the predictor, a kept Jacobian replaced by full Newton),
 * and the torques the actuated joints apply over it, applied_torques(z, x0, u, q, dt) at its
 * converged z (a control law solved inside the step, issue 34). A step that step() would split
 * into halves has no single torque over dt: NOT_CONVERGED, tau and x1 untouched. The torques are
 * evaluated into scratch before finish_step (c->rest: N >= NU entries, elsewhere a posture's zero
 * rates), so that a failure anywhere leaves both outputs untouched; x1 is then bitwise step()'s
 * from the same workspace. A composed step (nstage > 0) has no single z: UNAVAILABLE. */
CHAINGEN_LINKAGE int chaingen_control_torques(const chaingen_model *table, const double *x0,
                                              const double *u, int nu, const double *p, int np,
                                              double dt, double *tau, double *x1,
                                              const chaingen_options *options,
                                              const chaingen_workspace *workspace,
                                              int *iterations)
{
    const chaingen_model *const model = CG_MODEL(table);
    cg_solver solver, *c = &solver;
    double *torques;
    int i, spent = 0, status;
    if (model && (!model->applied_torques || model->nstage > 0)) {
        return CHAINGEN_UNAVAILABLE;
    }
    if (!x0 || !tau || !x1 || cg_adaptive_options(options)) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    status = cg_begin_step(model, workspace, c, x0, u, nu, p, np, dt);
    if (status != CHAINGEN_OK) {
        return status;
    }
    torques = c->rest;
    status = cg_solve_step(model, c, x0, u, p, dt, options, &spent);
    if (iterations) {
        *iterations = spent;
    }
    if (status == CHAINGEN_OK) {
        cg_step_arguments(model, c, c->z, x0, u, &dt);
        c->res[0] = torques;
        status = cg_evaluate(model->applied_torques, c);
        if (status != CHAINGEN_OK) {
            return status;
        }
        if (!cg_all_finite(torques, model->nu)) {
            return CHAINGEN_NONFINITE;
        }
        status = cg_finish_step(model, c, x0, u, dt, x1, NULL, options);
    }
    if (status != CHAINGEN_OK) {
        /* step() would split the step (advance): no single torque over dt. The whole step's
         * own status says why (Newton failed, not finite, a segment turned, a jump in energy). */
        return status;
    }
    for (i = 0; i < model->nu; ++i) {
        tau[i] = torques[i];
    }
    return CHAINGEN_OK;
}

/* A step as advance's first rung takes it (no split: the Jacobians are those of one step), and
 * the step map's Jacobians by the implicit function theorem: one factorisation of dF/dz at the
 * converged z, solved for the NCHAIN_SENS right-hand sides. Rows: the joint-space state s
 * (2N), or with chain_state (a composed es step's stages) the whole state x. `whole`: the step
 * is the entry point's own (dt > 0 and x0's segments checked here); otherwise a stage of a
 * composed step, whose dt may be negative and whose start the composition checked. */
static int cg_stage_sensitivities(const chaingen_model *table, const cg_solver *c, const double *x0,
                                  const double *u, const double *p, double dt, double *x1,
                                  double *ds_ds, double *ds_du, double *ds_dp,
                                  const chaingen_options *options, int *iterations, int whole)
{
    const chaingen_model *const model = CG_MODEL(table);
    const int nz = model->nz, nu = model->nu, np = model->np;
    const int R = CHAINGEN_NCHAIN(model->n_joints, model->nx, model->chain_state);
    const int C = CHAINGEN_NCHAIN_SENS(model->n_joints, model->nx, nu, np, model->chain_state);
    double *rhs;
    int i, j, k, status;
    if ((!p && np > 0) || !x1 || !ds_ds || (!ds_du && nu > 0) || (!ds_dp && np > 0)
        || (whole && (!(dt > 0.0) || !isfinite(dt) || cg_bad_values(model, x0, u)))) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    status = cg_derive(model, c, p);
    if (status != CHAINGEN_OK) {
        return status;
    }
    if (whole && model->nsegment > 0) {
        status = x0 ? cg_start_segments(model, c, x0) : CHAINGEN_OK;   /* finite: above */
        if (status != CHAINGEN_OK) {
            return status;
        }
    }
    status = cg_solve_step(model, c, x0, u, p, dt, options, iterations);
    if (status == CHAINGEN_OK) {
        status = cg_finish_step(model, c, x0, u, dt, x1, NULL, options);
    }
    if (status != CHAINGEN_OK) {
        return status;
    }
    /* dF/dz at the converged z, factorised once (the step's constants of this start, whatever
     * evaluated them last). */
    if (cg_step_constants(model, c, x0, u, dt) != CHAINGEN_OK) {
        return CHAINGEN_EVALUATION_FAILED;
    }
    if (model->arm_nh > 0 ? cg_newton_factors(model, c, model->newton_factors, c->z, x0, u, dt,
                                              c->residual)
                          : cg_evaluate_residual_jacobian(model, c, c->z, x0, u, p, dt, c->residual,
                                                          c->jacobian)) {
        return CHAINGEN_EVALUATION_FAILED;
    }
    if (cg_factorise(model, c)) {
        c->s->factors_valid = 0;
        return CHAINGEN_SINGULAR_JACOBIAN;
    }
    c->s->factors_valid = 1;   /* dF/dz at this step's solution: reusable */
    c->s->factors_dt = dt;
    /* Z = -J^-1 [F_x0 X_s, F_u, F_p]: one solve per column, in place. */
    rhs = c->sensitivity_rhs;
    cg_step_arguments(model, c, c->z, x0, u, &dt);
    c->res[0] = rhs;
    if (cg_evaluate(model->sensitivity_rhs, c)) {
        return CHAINGEN_EVALUATION_FAILED;
    }
    for (j = 0; j < C; ++j) {
        cg_solve_newton(model, c, rhs + j * nz);
    }
    /* ds1 = S_z Z + [S_s0, S_u, S_p]. */
    cg_step_arguments(model, c, c->z, x0, u, &dt);
    c->res[0] = c->s1_z;
    c->res[1] = ds_ds;
    k = 2;
    if (nu > 0) {
        c->res[k++] = ds_du;
    }
    if (np > 0) {
        c->res[k++] = ds_dp;
    }
    if (cg_evaluate(model->sensitivity_map, c)) {
        return CHAINGEN_EVALUATION_FAILED;
    }
    for (j = 0; j < C; ++j) {
        double *column = ds_ds + j * R;
        if (nu > 0 && j >= R && j < R + nu) {
            column = ds_du + (j - R) * R;
        }
        if (np > 0 && j >= R + nu) {
            column = ds_dp + (j - R - nu) * R;
        }
        for (i = 0; i < R; ++i) {
            double sum = 0.0;
            for (k = 0; k < nz; ++k) {
                sum += c->s1_z[i + k * R] * rhs[k + j * nz];
            }
            column[i] -= sum;
        }
    }
    if (!cg_all_finite(ds_ds, R * R)) {
        return CHAINGEN_NONFINITE;
    }
    if (nu > 0 && !cg_all_finite(ds_du, R * nu)) {
        return CHAINGEN_NONFINITE;
    }
    if (np > 0 && !cg_all_finite(ds_dp, R * np)) {
        return CHAINGEN_NONFINITE;
    }
    return CHAINGEN_OK;
}

/* The composed step's sensitivities by the chain rule through its stages: with the stage's
 * [S B] = [ds_ds ds_du ds_dp], the accumulated [D E] becomes [S D, S E + B]. Each stage is a step
 * as stage_sensitivities does it (no split steps). With chain_state the stages chain in x, mapped
 * to joint space at the ends (joint_maps). */
static int cg_composed_sensitivities(const chaingen_model *table, const cg_solver *c,
                                     const double *x0, const double *u, const double *p, double dt,
                                     double *x1, double *ds_ds, double *ds_du, double *ds_dp,
                                     const chaingen_options *options, int *iterations)
{
    const chaingen_model *const model = CG_MODEL(table);
    const int nx = model->nx, nu = model->nu, np = model->np, NS = 2 * model->n_joints;
    const int R = CHAINGEN_NCHAIN(model->n_joints, nx, model->chain_state);
    const int C = CHAINGEN_NCHAIN_SENS(model->n_joints, nx, nu, np, model->chain_state);
    double *stage = c->stage_sensitivities;
    double *composed = c->composed_sensitivities;
    const double *from = x0;
    int s, i, j, k, spent = 0, status = CHAINGEN_OK;
    if (!x0 || (!p && np > 0) || !x1 || !ds_ds || (!ds_du && nu > 0) || (!ds_dp && np > 0)
        || !(dt > 0.0) || !isfinite(dt) || cg_bad_values(model, x0, u)) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    if (model->nsegment > 0) {
        /* The start state's segments (the stages' later states are checked as their x1). */
        status = cg_derive(model, c, p);
        if (status == CHAINGEN_OK) {   /* x0 finite: cg_bad_values above */
            status = cg_start_segments(model, c, x0);
        }
        if (status != CHAINGEN_OK) {
            return status;
        }
    }
    for (s = 0; s < model->nstage && status == CHAINGEN_OK; ++s) {
        int stage_iterations = 0;
        double *to = s == model->nstage - 1 ? x1 : c->stage_state + (s % 2) * nx;
        status = cg_stage_sensitivities(model, c, from, u, p, model->stages[s] * dt, to, stage,
                                        stage + R * R, stage + R * (R + nu), options,
                                        &stage_iterations, 0);
        spent += stage_iterations;
        if (status != CHAINGEN_OK) {
            break;
        }
        if (s == 0) {
            memcpy(composed, stage, sizeof(double) * (size_t)R * (size_t)C);
        } else {
            double *column = c->column;
            for (j = 0; j < C; ++j) {
                for (i = 0; i < R; ++i) {
                    double sum = j < R ? 0.0 : stage[i + j * R];
                    for (k = 0; k < R; ++k) {
                        sum += stage[i + k * R] * composed[k + j * R];
                    }
                    column[i] = sum;
                }
                memcpy(composed + j * R, column, sizeof(double) * (size_t)R);
            }
        }
        from = to;
    }
    if (iterations) {
        *iterations = spent;
    }
    if (status != CHAINGEN_OK) {
        return status;
    }
    if (model->chain_state) {
        /* To joint space, with X_s = dx0/ds0 at s0 = outputs(x0) and S = ds1/dx1 at the end:
         * ds_ds = S D X_s, ds_du = S E_u, ds_dp = S (D X_p + E_p) + S_p. */
        c->arg[0] = x0;
        c->arg[1] = x1;
        if (np > 0) {
            c->arg[2] = c->q;
        }
        c->res[0] = c->x0_s0;
        c->res[1] = c->s1_x1;
        if (np > 0) {
            c->res[2] = c->x0_p;
            c->res[3] = c->s1_p;
        }
        if (cg_evaluate(model->joint_maps, c)) {
            return CHAINGEN_EVALUATION_FAILED;
        }
        for (j = 0; j < NS + nu + np; ++j) {
            double *column = c->chain_column;   /* D X_s, E_u or D X_p + E_p: column j */
            double *out = ds_ds + j * NS;
            for (i = 0; i < nx; ++i) {
                double sum = 0.0;
                if (j < NS) {
                    for (k = 0; k < nx; ++k) {
                        sum += composed[i + k * nx] * c->x0_s0[k + j * nx];
                    }
                } else if (j < NS + nu) {
                    sum = composed[i + (nx + j - NS) * nx];
                } else {
                    sum = composed[i + (nx + nu + j - NS - nu) * nx];
                    for (k = 0; k < nx; ++k) {
                        sum += composed[i + k * nx] * c->x0_p[k + (j - NS - nu) * nx];
                    }
                }
                column[i] = sum;
            }
            if (nu > 0 && j >= NS && j < NS + nu) {
                out = ds_du + (j - NS) * NS;
            }
            if (np > 0 && j >= NS + nu) {
                out = ds_dp + (j - NS - nu) * NS;
            }
            for (i = 0; i < NS; ++i) {
                double sum = 0.0;
                for (k = 0; k < nx; ++k) {
                    sum += c->s1_x1[i + k * NS] * column[k];
                }
                if (np > 0 && j >= NS + nu) {
                    sum += c->s1_p[i + (j - NS - nu) * NS];
                }
                if (!isfinite(sum)) {
                    return CHAINGEN_NONFINITE;
                }
                out[i] = sum;
            }
        }
    } else {
        memcpy(ds_ds, composed, sizeof(double) * (size_t)NS * (size_t)NS);
        if (nu > 0) {
            memcpy(ds_du, composed + NS * NS, sizeof(double) * (size_t)NS * (size_t)nu);
        }
        if (np > 0) {
            memcpy(ds_dp, composed + NS * (NS + nu), sizeof(double) * (size_t)NS * (size_t)np);
        }
    }
    return CHAINGEN_OK;
}

CHAINGEN_LINKAGE int chaingen_step_sensitivities(const chaingen_model *table, const double *x0,
                                                 const double *u, int nu, const double *p, int np,
                                                 double dt, double *x1, double *ds_ds,
                                                 double *ds_du, double *ds_dp,
                                                 const chaingen_options *options,
                                                 const chaingen_workspace *workspace,
                                                 int *iterations)
{
    const chaingen_model *const model = CG_MODEL(table);
    cg_solver solver;
    if (model && !model->sensitivities) {
        return CHAINGEN_UNAVAILABLE;
    }
    if (cg_bad_view(model, workspace) || cg_bad_sizes(model, u, nu, 0, p, np)
        || cg_adaptive_options(options)) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    cg_carve(model, workspace, &solver);
    if (model->nstage > 0) {
        return cg_composed_sensitivities(model, &solver, x0, u, p, dt, x1, ds_ds, ds_du, ds_dp,
                                         options, iterations);
    }
    return cg_stage_sensitivities(model, &solver, x0, u, p, dt, x1, ds_ds, ds_du, ds_dp, options,
                                  iterations, 1);
}

/* s = (phi, omega) of the state x, s[2 N]. */
static int cg_joint_state(const chaingen_model *table, const cg_solver *c, const double *x,
                          const double *p, double *s)
{
    const chaingen_model *const model = CG_MODEL(table);
    return cg_outputs(model, c, x, p, s, s + model->n_joints, NULL, NULL);
}

/* Adaptive steps (options->rtol > 0 or options->atol > 0). Each sample interval of length dt is
 * covered by steps of the model's order whose lengths a PI controller chooses, landing on the
 * interval's end. The local error of a step of length h from x is estimated by step doubling:
 * one step of h and two of h/2 from x, in the joint-space state s = (phi, omega),
 *     e = (s_two_halves - s_one_step) / (2^ORDER - 1),
 * and the step passes when max_i |e_i| / (atol + rtol max(|s_i(x)|, |s_i(two halves)|)) <= 1,
 * over the model's error_entries first entries of s: 2N (angles and rates), or N, the angles
 * alone, for "es" at order 2, whose rates are off the velocity constraint C(q) v = 0 by O(dt^2)
 * in every step, without accumulating: step doubling would see that, not the local error (at
 * order 4 the rates come from the projected velocity and are tested too).
 * The two halves are kept (no extrapolation, which would lose the scheme's structure): "es"
 * conserves energy on any sequence of step lengths, so its energy stays at round-off while the
 * step adapts. A step that Newton fails (its ladder without splits), or that collapses a spring
 * segment, is refused and retried at NEWTON_FACTOR of its length, as is one whose error test
 * fails (at the controller's length); below MIN_STEP_FRACTION dt the run stops with the last
 * failure's status, or STEP_TOO_SMALL when the error test refused it. PI control (Gustafsson;
 * the exponents of Hairer and Wanner's DOPRI codes):
 *     h_new = h SAFETY err^-(0.7 / (ORDER + 1)) err_previous^(0.4 / (ORDER + 1)).
 * rtol and atol are 0 or at least CHAINGEN_MIN_TOLERANCE (below it the error estimate is
 * round-off). An entry's scale is at least ESTIMATE_FLOOR times the largest magnitude of its
 * block (the angles, at least 1 rad; the rates): the two results differ by round-off of that
 * size even as h -> 0 (an angle comes from coordinates of the chain's size, a relative rate
 * from the links' rates), so an entry near zero with atol = 0 (or atol below that round-off)
 * would refuse every step down to the floor of MIN_STEP_FRACTION dt. A model whose control law
 * is held over the step (held_control) takes no adaptive steps: cg_run refuses them with
 * BAD_ARGUMENT, as the law's hold period would become the step's. From x0 over the interval
 * dt to x1; the controller's proposal carries over from interval to interval in the
 * workspace. */
static int cg_adaptive_interval(const chaingen_model *table, const cg_solver *c, const double *x0,
                                const double *u, const double *p, double dt, double *x1,
                                double *flows, const chaingen_options *options, int *iterations,
                                chaingen_stats *counters)
{
    const chaingen_model *const model = CG_MODEL(table);
    chaingen_workspace_scalars *ws = c->s;
    const int n = model->n_joints, nx = model->nx, order = model->order;
    const double alpha = 0.7 / (order + 1), beta = 0.4 / (order + 1);
    double *start = c->joint_start, *whole = c->joint_whole, *ends = c->joint_ends;
    double *from = c->adaptive_state;
    double *one = c->adaptive_state + nx;
    double *middle = c->adaptive_state + 2 * nx;
    double *two = c->adaptive_state + 3 * nx;
    double halves[2][2], total[2] = {0.0, 0.0};
    double elapsed = 0.0;
    int status, failure = CHAINGEN_STEP_TOO_SMALL, refused = 0, i;
    memcpy(from, x0, sizeof(double) * (size_t)nx);
    status = cg_joint_state(model, c, from, p, start);
    if (!(ws->proposed_dt > 0.0)) {
        ws->proposed_dt = dt;
        ws->previous_error = 1.0;
    }
    while (status == CHAINGEN_OK && elapsed < dt) {
        double remaining = dt - elapsed, h = ws->proposed_dt, error = 0.0, factor;
        int landing = 0;
        if (h >= remaining * (1.0 - 1e-12)) {
            h = remaining;
            landing = 1;
        } else if (h > 0.5 * remaining) {
            h = 0.5 * remaining;   /* two even steps rather than one and a sliver */
        }
        if (h < CHAINGEN_MIN_STEP_FRACTION * dt) {
            status = failure;
            break;
        }
        status = cg_take_step(model, c, from, u, p, h, one, NULL, options, iterations,
                              CHAINGEN_MAX_SPLIT);
        if (status == CHAINGEN_OK) {
            status = cg_take_step(model, c, from, u, p, 0.5 * h, middle, halves[0], options,
                                  iterations, CHAINGEN_MAX_SPLIT);
        }
        if (status == CHAINGEN_OK) {
            status = cg_take_step(model, c, middle, u, p, 0.5 * h, two, halves[1], options,
                                  iterations, CHAINGEN_MAX_SPLIT);
        }
        if (status == CHAINGEN_OK) {
            status = cg_joint_state(model, c, one, p, whole);
        }
        if (status == CHAINGEN_OK) {
            status = cg_joint_state(model, c, two, p, ends);
        }
        if (status == CHAINGEN_OK) {
            double block[2] = {1.0, 0.0};   /* the angles' and the rates' largest magnitudes */
            for (i = 0; i < model->error_entries; ++i) {
                double size = fmax(fabs(start[i]), fabs(ends[i]));
                block[i >= n] = fmax(block[i >= n], size);
            }
            for (i = 0; i < model->error_entries; ++i) {
                double difference = ends[i] - whole[i];
                double scale = options->atol + options->rtol * fmax(fabs(start[i]), fabs(ends[i]));
                double ratio;
                if (i < n) {
                    difference = remainder(difference, CG_TWO_PI);   /* angles are wrapped */
                }
                scale = fmax(scale, CG_ESTIMATE_FLOOR * block[i >= n]);
                /* 0 / 0 (an entry and its block at rest, atol = 0) is no error. */
                ratio = difference == 0.0
                    ? 0.0 : fabs(difference) / ((double)((1 << order) - 1) * scale);
                if (!(ratio <= error)) {
                    error = ratio;   /* NaN propagates */
                }
            }
            if (!isfinite(error)) {
                status = CHAINGEN_NONFINITE;
            }
        }
        if (cg_shorter_may_pass(model, status)) {
            /* Newton or the step failed: refuse it and try a much shorter one. */
            failure = status;
            status = CHAINGEN_OK;
            ++counters->rejected_steps;
            ws->proposed_dt = CG_NEWTON_FACTOR * h;
            ws->previous_error = 1.0;
            refused = 1;
            continue;
        }
        if (status != CHAINGEN_OK) {
            break;
        }
        if (error <= 1.0) {
            double proposal;
            memcpy(from, two, sizeof(double) * (size_t)nx);
            memcpy(start, ends, sizeof(double) * 2 * (size_t)n);
            elapsed = landing ? dt : elapsed + h;
            if (model->flows) {
                total[0] += halves[0][0] + halves[1][0];
                total[1] += halves[0][1] + halves[1][1];
            }
            counters->accepted_steps += 2;   /* two steps of h/2 */
            if (counters->smallest_dt == 0.0 || 0.5 * h < counters->smallest_dt) {
                counters->smallest_dt = 0.5 * h;
            }
            if (0.5 * h > counters->largest_dt) {
                counters->largest_dt = 0.5 * h;
            }
            factor = CG_SAFETY * pow(fmax(error, 1e-10), -alpha) * pow(ws->previous_error, beta);
            factor = fmin(CG_MAX_FACTOR, fmax(CG_MIN_FACTOR, factor));
            if (refused) {
                factor = fmin(factor, 1.0);   /* no growth right after a refusal */
            }
            proposal = h * factor;
            /* A step shortened to land keeps the controller's longer proposal. */
            if (!landing || proposal > ws->proposed_dt) {
                ws->proposed_dt = proposal;
            }
            ws->previous_error = fmax(error, 1e-4);
            failure = CHAINGEN_STEP_TOO_SMALL;
            refused = 0;
        } else {
            ++counters->rejected_steps;
            factor = fmax(CG_MIN_FACTOR, CG_SAFETY * pow(error, -1.0 / (order + 1)));
            ws->proposed_dt = h * fmin(factor, 0.9);
            failure = CHAINGEN_STEP_TOO_SMALL;
            refused = 1;
        }
    }
    if (status == CHAINGEN_OK) {
        memcpy(x1, from, sizeof(double) * (size_t)nx);
        if (model->flows && flows) {
            flows[0] = total[0];
            flows[1] = total[1];
        }
    }
    return status;
}

CHAINGEN_LINKAGE long chaingen_sample_count(const chaingen_model *table, long n_steps, long every)
{
    const chaingen_model *const model = CG_MODEL(table);
    long whole;
    if (n_steps < 0 || every < 1) {
        return 0;
    }
    if (!model || model->nsample < 1) {
        return -1;
    }
    whole = n_steps / every;   /* the rows are whole + 1 */
    if (whole >= LONG_MAX / model->nsample
        || (size_t)whole >= SIZE_MAX / (sizeof(double) * (size_t)model->nsample)) {
        return -1;   /* more rows than memory can address */
    }
    return whole + 1;
}

/* Neumaier's compensated sum: the energy flows of many steps, accurate to round-off. */
typedef struct {
    double sum;
    double compensation;
} cg_compensated_sum;

static void cg_add(cg_compensated_sum *total, double value)
{
    double t = total->sum + value;
    if (fabs(total->sum) >= fabs(value)) {
        total->compensation += (total->sum - t) + value;
    } else {
        total->compensation += (value - t) + total->sum;
    }
    total->sum = t;
}

/* Write one sample row: t, phi, omega, energy, constraint error, and with energy flows the
 * input work and the energy dissipated. */
static int cg_write_sample(const chaingen_model *table, const cg_solver *c, const double *x,
                           const double *p, double t, const cg_compensated_sum *totals, double *row)
{
    const chaingen_model *const model = CG_MODEL(table);
    const int n = model->n_joints;
    row[0] = t;
    if (model->flows) {
        row[3 + 2 * n] = totals[0].sum + totals[0].compensation;
        row[4 + 2 * n] = totals[1].sum + totals[1].compensation;
    }
    return cg_outputs(model, c, x, p, row + 1, row + 1 + n, row + 1 + 2 * n, row + 2 + 2 * n);
}

/* The loop of simulate_observed and simulate_controlled: the inputs of step k from u, or, with
 * u NULL, from the controller, called every `hold` steps with the joint state (the outputs of the
 * state the step starts from) and held in between (zeros without a controller); recorded into
 * torques (may be NULL). */
static int cg_run(const chaingen_model *table, const cg_solver *c,
                  const chaingen_workspace *workspace, const double *x0, double t0, double dt,
                  long n_steps, long every, const double *u, const double *p,
                  const chaingen_options *options, double *samples, double *x_final,
                  chaingen_stats *stats, chaingen_observer observer, void *context, long interval,
                  chaingen_control *control, chaingen_controller controller,
                  void *controller_context, long hold, double *torques)
{
    const chaingen_model *const model = CG_MODEL(table);
    const int nx = model->nx, nu = model->nu;
    chaingen_options defaults;
    chaingen_stats counters;
    cg_compensated_sum totals[2] = {{0.0, 0.0}, {0.0, 0.0}};
    double *phi = c->phi, *omega = c->omega, *held = c->held;   /* the controller's arguments */
    double *current, *next;
    long k;
    int status, adaptive;
    if (!x0 || (!p && model->np > 0) || !samples || n_steps < 0 || every < 1 || !(dt > 0.0)
        || !isfinite(dt) || !isfinite(t0) || interval < 1
        || chaingen_sample_count(model, n_steps, every) < 0) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    if (!options) {
        defaults = model->defaults;
        options = &defaults;
    }
    if (!(options->rtol == 0.0
          || (options->rtol >= CHAINGEN_MIN_TOLERANCE && isfinite(options->rtol)))
        || !(options->atol == 0.0
             || (options->atol >= CHAINGEN_MIN_TOLERANCE && isfinite(options->atol)))) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    adaptive = options->rtol > 0.0 || options->atol > 0.0;
    if (adaptive && model->held_control) {
        return CHAINGEN_BAD_ARGUMENT;   /* the held law's period is dt, not an adaptive step */
    }
    memset(&counters, 0, sizeof counters);
    if (!adaptive && n_steps > 0) {
        counters.smallest_dt = dt;
        counters.largest_dt = dt;
    }
    chaingen_workspace_init(model, workspace);   /* a new trajectory: no history carried in */
    memset(held, 0, sizeof(double) * (size_t)nu);
    status = cg_derive(model, c, p);
    if (status != CHAINGEN_OK) {
        return status;
    }
    current = c->state[0];
    next = c->state[1];
    memcpy(current, x0, sizeof(double) * (size_t)nx);
    status = cg_write_sample(model, c, current, p, t0, totals, samples);
    if (model->nsegment > 0 && status == CHAINGEN_OK) {
        /* The start; every later state is a step's checked x1. */
        status = cg_start_segments(model, c, current);
    }
    if (control && control->stop && status == CHAINGEN_OK) {
        status = CHAINGEN_INTERRUPTED;   /* stopped before it began: no step */
    }
    for (k = 1; k <= n_steps && status == CHAINGEN_OK; ++k) {
        int iterations = 0;
        double flows[2] = {0.0, 0.0};   /* written by a completed interval */
        const double *inputs = NULL;
        if (nu > 0) {
            inputs = u ? u + (k - 1) * nu : held;
            if (controller && (k - 1) % hold == 0) {
                double energy, error;
                status = cg_outputs(model, c, current, p, phi, omega, &energy, &error);
                if (status == CHAINGEN_OK
                    && controller(k - 1, t0 + (double)(k - 1) * dt, phi, omega, held,
                                  controller_context)) {
                    status = CHAINGEN_INTERRUPTED;
                }
                if (status != CHAINGEN_OK) {
                    break;
                }
            }
            if (torques && (k - 1) % every == 0) {   /* recorded as the samples are */
                memcpy(torques + ((k - 1) / every) * nu, inputs, sizeof(double) * (size_t)nu);
            }
        }
        c->s->step_fallbacks = 0;
        c->s->step_splits = 0;
        if (adaptive) {
            status = cg_adaptive_interval(model, c, current, inputs, p, dt, next, flows, options,
                                          &iterations, &counters);
        } else {
            status = cg_take_step(model, c, current, inputs, p, dt, next, flows, options,
                                  &iterations, 0);
            counters.accepted_steps = k;
        }
        counters.full_newton_fallbacks += c->s->step_fallbacks;
        counters.split_steps += c->s->step_splits > 0;
        if (status != CHAINGEN_OK) {
            counters.failed_iterations = iterations;
            break;
        }
        {
            double *swap = current;
            current = next;
            next = swap;
        }
        if (model->flows) {
            cg_add(&totals[0], flows[0]);
            cg_add(&totals[1], flows[1]);
        }
        counters.steps = k;
        counters.newton_iterations += iterations;
        if (iterations > counters.max_newton_iterations) {
            counters.max_newton_iterations = iterations;
        }
        if (k % every == 0) {
            status = cg_write_sample(model, c, current, p, t0 + (double)k * dt, totals,
                                     samples + (k / every) * model->nsample);
        }
        if (observer && status == CHAINGEN_OK && k % interval == 0 && observer(k, context)) {
            status = CHAINGEN_INTERRUPTED;
        }
        if (control) {
            control->steps = k;
            if (control->stop && status == CHAINGEN_OK) {
                status = CHAINGEN_INTERRUPTED;
            }
        }
    }
    if (x_final) {
        memcpy(x_final, current, sizeof(double) * (size_t)nx);
    }
    if (stats) {
        *stats = counters;
    }
    return status;
}

CHAINGEN_LINKAGE int chaingen_simulate_observed(const chaingen_model *table, const double *x0,
                                                double t0, double dt, long n_steps, long every,
                                                const double *u, int nu, const double *p, int np,
                                                const chaingen_options *options,
                                                const chaingen_workspace *workspace,
                                                double *samples, double *x_final,
                                                chaingen_stats *stats, chaingen_observer observer,
                                                void *context, long interval,
                                                chaingen_control *control)
{
    const chaingen_model *const model = CG_MODEL(table);
    cg_solver solver;
    if (cg_bad_view(model, workspace) || cg_bad_sizes(model, u, nu, 1, p, np)) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    cg_carve(model, workspace, &solver);
    /* u NULL: the loop's held inputs, zeros without a controller. */
    return cg_run(model, &solver, workspace, x0, t0, dt, n_steps, every, u, p, options, samples,
                  x_final, stats, observer, context, interval, control, NULL, NULL, 1, NULL);
}

CHAINGEN_LINKAGE int chaingen_simulate_controlled(const chaingen_model *table, const double *x0,
                                                  double t0, double dt, long n_steps, long every,
                                                  chaingen_controller controller, void *context,
                                                  long hold, const double *p, int np,
                                                  const chaingen_options *options,
                                                  const chaingen_workspace *workspace,
                                                  double *samples, double *torques, double *x_final,
                                                  chaingen_stats *stats, chaingen_control *control)
{
    const chaingen_model *const model = CG_MODEL(table);
    cg_solver solver;
    if (model && model->nu <= 0) {
        return CHAINGEN_UNAVAILABLE;
    }
    if (cg_bad_view(model, workspace) || cg_bad_sizes(model, NULL, model->nu, 1, p, np)) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    if (!controller || hold < 1) {
        return CHAINGEN_BAD_ARGUMENT;
    }
    cg_carve(model, workspace, &solver);
    return cg_run(model, &solver, workspace, x0, t0, dt, n_steps, every, NULL, p, options, samples,
                  x_final, stats, NULL, NULL, 1, control, controller, context, hold, torques);
}

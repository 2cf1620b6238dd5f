/* The shooting stages of a robot's optimal-control problems in C: one library per robot,
 * horizon, interval length and integrator, written by kindyngen/control/native.py.
 *
 * Included by a glue file that defines NDOF, NINT (intervals), NSTAGE (fd evaluations per
 * interval), NSUB (substeps), NIN (inner rows per interval: the 2 NDOF states at the ends of
 * substeps 1..NSUB-1, or 0), KDG_FD / KDG_FDD / KDG_TAU (the robot's generated fd,
 * fd_derivatives, tau, row-major), the stage tables kdg_gq, kdg_aq, kdg_bv, kdg_ogq, kdg_oaq,
 * kdg_obv (kindyngen/control/integrators.py: stage states and substep ends as linear forms of
 * (q, v, a_0..a_{S-1})), the CasADi-generated helpers kdg_idh (Hessian of m' tau(y) over
 * y = (q, qd, qdd), dense 3n x 3n), kdg_term / kdg_jterm / kdg_hterm (terminal rows: flange
 * position - goal, qd; their Jacobian 10 x 14 column-major; Hessian of l' term), and the
 * sparsity tables kdg_sp_jac, kdg_sp_hess, kdg_sp_jp (CasADi compressed columns).
 *
 * Re-entrant: no globals but constant tables, no allocation; every result is a function of
 * the arguments only (the forward chain of an interval lives on the stack of the call).
 *
 * Reach NLP: z = (x_0, u_0, ..., x_{N-1}, u_{N-1}, x_N), x = (q, qd), u = tau;
 * p = (x_init, goal); rows per interval k: gap_k = x_{k+1} - F(x_k, u_k), at k = 0 also
 * x_0 - x_init, then the inner states x_{k,1..M-1}; last the terminal rows. */
#include <string.h>

#define NQ NDOF
#define NX (2 * NQ)
#define NW (3 * NQ)                 /* (x_k, u_k) */
#define NTERM (3 + NQ)
#define NZ (NINT * NW + NX)
#define SB (NX + NIN)               /* rows of an interval (interval 0: + NX for x_0 - x_init) */
#define NG (NINT * SB + NX + NTERM)
#define NP (NX + 3)

/* forward chain of one interval */
typedef struct {
    double y[NSTAGE][NW];                 /* stage states (q_i, v_i, a_i) */
    double dq[NSTAGE][NQ * NQ], dv[NSTAGE][NQ * NQ], minv[NSTAGE][NQ * NQ];  /* fd_derivatives */
    double dy[NSTAGE][NW * NW];           /* d y_i / d w, row-major (rows q, v, a) */
    double xo[NSUB][NX];                  /* ends of substeps 1..M (the last: F) */
    double dxo[NSUB][NX * NW];            /* their Jacobians d x_o / d w, row-major */
} chain_t;

static int row_gap(int k) { return k * SB + (k > 0 ? NX : 0); }
static int row_inner(int k) { return row_gap(k) + NX + (k == 0 ? NX : 0); }

/* values (derivs = 0) or values and first derivatives (derivs = 1) of one interval */
static void chain(const double *x, const double *u, chain_t *c, int derivs)
{
    double a[NSTAGE][NQ];
    int i, j, r, col, m, o;
    for (i = 0; i < NSTAGE; i++) {
        double *q = c->y[i], *v = c->y[i] + NQ;
        for (r = 0; r < NQ; r++) {
            double sq = x[r] + kdg_gq[i] * x[NQ + r], sv = x[NQ + r];
            for (j = 0; j < i; j++) {
                if (kdg_aq[i][j] != 0.0) sq += kdg_aq[i][j] * a[j][r];
                if (kdg_bv[i][j] != 0.0) sv += kdg_bv[i][j] * a[j][r];
            }
            q[r] = sq;
            v[r] = sv;
        }
        KDG_FD(q, v, u, a[i]);
        memcpy(c->y[i] + NX, a[i], sizeof a[i]);
        if (derivs) {
            double *dY = c->dy[i];
            double *dQ = dY, *dV = dY + NQ * NW, *dA = dY + NX * NW;
            KDG_FDD(q, v, u, c->dq[i], c->dv[i], c->minv[i]);
            /* dq_i = [I, gq_i I, 0] + sum_j aq_ij da_j; dv_i = [0, I, 0] + sum_j bv_ij da_j */
            memset(dQ, 0, 2 * NQ * NW * sizeof(double));
            for (r = 0; r < NQ; r++) {
                dQ[r * NW + r] = 1.0;
                dQ[r * NW + NQ + r] = kdg_gq[i];
                dV[r * NW + NQ + r] = 1.0;
            }
            for (j = 0; j < i; j++) {
                const double ca = kdg_aq[i][j], cb = kdg_bv[i][j];
                const double *dAj = c->dy[j] + NX * NW;
                if (ca != 0.0) for (col = 0; col < NQ * NW; col++) dQ[col] += ca * dAj[col];
                if (cb != 0.0) for (col = 0; col < NQ * NW; col++) dV[col] += cb * dAj[col];
            }
            /* da_i = Dq dq_i + Dv dv_i + [0 0 Minv] */
            for (r = 0; r < NQ; r++) {
                double *row = dA + r * NW;
                const double *Dq = c->dq[i] + r * NQ, *Dv = c->dv[i] + r * NQ;
                for (col = 0; col < NW; col++) row[col] = 0.0;
                for (m = 0; m < NQ; m++) {
                    const double p = Dq[m], s = Dv[m];
                    const double *zq = dQ + m * NW, *zv = dV + m * NW;
                    for (col = 0; col < NW; col++) row[col] += p * zq[col] + s * zv[col];
                }
                for (col = 0; col < NQ; col++) row[NX + col] += c->minv[i][r * NQ + col];
            }
        }
    }
    for (o = 0; o < NSUB; o++) {
        for (r = 0; r < NQ; r++) {
            double sq = x[r] + kdg_ogq[o] * x[NQ + r], sv = x[NQ + r];
            for (j = 0; j < NSTAGE; j++) {
                if (kdg_oaq[o][j] != 0.0) sq += kdg_oaq[o][j] * a[j][r];
                if (kdg_obv[o][j] != 0.0) sv += kdg_obv[o][j] * a[j][r];
            }
            c->xo[o][r] = sq;
            c->xo[o][NQ + r] = sv;
        }
        if (derivs) {
            double *D = c->dxo[o];
            memset(D, 0, NX * NW * sizeof(double));
            for (r = 0; r < NQ; r++) {
                D[r * NW + r] = 1.0;
                D[r * NW + NQ + r] = kdg_ogq[o];
                D[(NQ + r) * NW + NQ + r] = 1.0;
            }
            for (j = 0; j < NSTAGE; j++) {
                const double ca = kdg_oaq[o][j], cb = kdg_obv[o][j];
                const double *dAj = c->dy[j] + NX * NW;
                if (ca != 0.0) for (col = 0; col < NQ * NW; col++) D[col] += ca * dAj[col];
                if (cb != 0.0) for (col = 0; col < NQ * NW; col++) D[NQ * NW + col] += cb * dAj[col];
            }
        }
    }
}

/* CasADi-generated helpers through their generic interface; work arrays on the stack */
static void call_helper(int (*f)(const casadi_real **, casadi_real **, casadi_int *, casadi_real *, int),
                        const double *a0, const double *a1, double *r0)
{
    const casadi_real *arg[KDG_SZARG];
    casadi_real *res[KDG_SZRES];
    casadi_int iw[KDG_SZIW];
    casadi_real w[KDG_SZW];
    arg[0] = a0;
    arg[1] = a1;
    res[0] = r0;
    f(arg, res, iw, w, 0);
}

static void eval_g(const double *zz, const double *p, double *g)
{
    int k, r, o;
    double term[NTERM];
    chain_t c;
    for (k = 0; k < NINT; k++) {
        const double *x1 = zz + (k + 1) * NW;
        double *gk = g + row_gap(k), *gi = g + row_inner(k);
        chain(zz + k * NW, zz + k * NW + NX, &c, 0);
        for (r = 0; r < NX; r++) gk[r] = x1[r] - c.xo[NSUB - 1][r];
        for (o = 0; o < NSUB - 1 && NIN > 0; o++)
            for (r = 0; r < NX; r++) gi[o * NX + r] = c.xo[o][r];
    }
    for (r = 0; r < NX; r++) g[NX + r] = zz[r] - p[r];
    call_helper(kdg_term, zz + NINT * NW, p + NX, term);
    memcpy(g + NG - NTERM, term, sizeof term);
}

/* Jacobian values in the order of kdg_sp_jac (column by column, rows increasing) */
static void eval_jac(const double *zz, const double *p, double *J)
{
    double jt[NTERM * NX];
    int k, o, r, col;
    long nz = 0;
    chain_t c;
    call_helper(kdg_jterm, zz + NINT * NW, p + NX, jt);      /* dense, column-major */
    for (k = 0; k < NINT; k++) {
        chain(zz + k * NW, zz + k * NW + NX, &c, 1);
        for (col = 0; col < NW; col++) {
            if (col < NX && k >= 1) J[nz++] = 1.0;            /* x_k in gap_{k-1} */
            for (r = 0; r < NX; r++) J[nz++] = -c.dxo[NSUB - 1][r * NW + col];
            if (col < NX && k == 0) J[nz++] = 1.0;            /* x_0 - x_init */
            for (o = 0; o < NSUB - 1 && NIN > 0; o++)
                for (r = 0; r < NX; r++) J[nz++] = c.dxo[o][r * NW + col];
        }
    }
    for (col = 0; col < NX; col++) {
        J[nz++] = 1.0;
        for (r = 0; r < NTERM; r++) J[nz++] = jt[r + NTERM * col];
    }
}

/* upper triangle (row-major, Hw[r * NW + col] for col >= r) of the Hessian over w = (x, u) of
 * sum_o mu[o]' x_o(w): the substep ends' multipliers mu (the last: the interval's end F), from
 * the inverse dynamics' Hessian with the stage multipliers by back substitution */
static void interval_hessian(const chain_t *c, const double mu[NSUB][NX], double *Hw)
{
    double Hid[NW * NW];
    double T[NQ * NW], U[NQ * NW], W[NQ * NW];
    double b[NSTAGE][NQ], rho[NSTAGE][NQ], lam[NSTAGE][NQ];
    int i, j, r, m, o, col;
    /* b = -F_a' mu over every substep end */
    for (i = 0; i < NSTAGE; i++)
        for (r = 0; r < NQ; r++) {
            double s = 0.0;
            for (o = 0; o < NSUB; o++) s += kdg_oaq[o][i] * mu[o][r] + kdg_obv[o][i] * mu[o][NQ + r];
            b[i][r] = -s;
        }
    /* back substitution R_a' lam = b: rho_i = b_i + sum_{j > i} (aq_ji Dq_j' + bv_ji Dv_j') rho_j,
     * lam_i = Minv_i rho_i */
    for (i = NSTAGE - 1; i >= 0; i--) {
        for (r = 0; r < NQ; r++) rho[i][r] = b[i][r];
        for (j = i + 1; j < NSTAGE; j++) {
            const double ca = kdg_aq[j][i], cb = kdg_bv[j][i];
            if (ca != 0.0)
                for (r = 0; r < NQ; r++)
                    for (m = 0; m < NQ; m++) rho[i][r] += ca * c->dq[j][m * NQ + r] * rho[j][m];
            if (cb != 0.0)
                for (r = 0; r < NQ; r++)
                    for (m = 0; m < NQ; m++) rho[i][r] += cb * c->dv[j][m * NQ + r] * rho[j][m];
        }
        for (r = 0; r < NQ; r++) {
            double s = 0.0;
            for (m = 0; m < NQ; m++) s += c->minv[i][r * NQ + m] * rho[i][m];
            lam[i][r] = s;
        }
    }
    memset(Hw, 0, NW * NW * sizeof(double));
    for (i = 0; i < NSTAGE; i++) {
        const double *dY = c->dy[i];
        const double *dQ = dY, *dV = dY + NQ * NW, *dA = dY + NX * NW;
        call_helper(kdg_idh, c->y[i], lam[i], Hid);         /* symmetric, dense */
        /* blocks of Hid: qq, qv, qa, vv (tau is linear in qdd, no qd-qdd terms: checked
         * when the library is written) */
        for (r = 0; r < NQ; r++) {
            double *t = T + r * NW, *u_ = U + r * NW, *w = W + r * NW;
            for (col = 0; col < NW; col++) t[col] = u_[col] = w[col] = 0.0;
            for (m = 0; m < NQ; m++) {
                const double hqq = Hid[r * NW + m], hqv = Hid[r * NW + NQ + m], hqa = Hid[r * NW + NX + m];
                const double hvq = Hid[(NQ + r) * NW + m], hvv = Hid[(NQ + r) * NW + NQ + m];
                const double haq = Hid[(NX + r) * NW + m];
                const double *q_ = dQ + m * NW, *v_ = dV + m * NW, *a_ = dA + m * NW;
                for (col = 0; col < NW; col++) {
                    t[col] += hqq * q_[col] + hqv * v_[col] + hqa * a_[col];
                    u_[col] += hvq * q_[col] + hvv * v_[col];
                    w[col] += haq * q_[col];
                }
            }
        }
        for (m = 0; m < NQ; m++) {
            const double *q_ = dQ + m * NW, *v_ = dV + m * NW, *a_ = dA + m * NW;
            const double *t = T + m * NW, *u_ = U + m * NW, *w = W + m * NW;
            for (o = 0; o < NW; o++) {
                const double qa = q_[o], va = v_[o], aa = a_[o];
                double *hr = Hw + o * NW;
                if (qa == 0.0 && va == 0.0 && aa == 0.0) continue;
                for (col = o; col < NW; col++) hr[col] += qa * t[col] + va * u_[col] + aa * w[col];
            }
        }
    }
}

/* upper triangle of the Hessian of lam_f f + lam_g' g (f = h sum |u_k|^2), block by block */
static void eval_hess(const double *zz, const double *p, double lam_f, const double *lam_g, double *Hnz)
{
    double Hw[NW * NW], ht[NX * NX];
    double mu[NSUB][NX];
    int k, r, o;
    long nz = 0;
    chain_t c;
    (void)p;
    for (k = 0; k < NINT; k++) {
        chain(zz + k * NW, zz + k * NW + NX, &c, 1);
        /* multipliers of the substep ends: the gap row is x_{k+1} - F (mu = -lam), an inner
         * row the state itself (mu = lam) */
        for (r = 0; r < NX; r++) mu[NSUB - 1][r] = -lam_g[row_gap(k) + r];
        for (o = 0; o < NSUB - 1 && NIN > 0; o++)
            for (r = 0; r < NX; r++) mu[o][r] = lam_g[row_inner(k) + o * NX + r];
        for (o = 0; o < NSUB - 1 && NIN == 0; o++)
            for (r = 0; r < NX; r++) mu[o][r] = 0.0;
        interval_hessian(&c, mu, Hw);
        for (r = 0; r < NQ; r++) Hw[(NX + r) * NW + NX + r] += 2 * HSTEP * lam_f;
        for (o = 0; o < NW; o++)
            for (r = 0; r <= o; r++) Hnz[nz++] = Hw[r * NW + o];
    }
    call_helper(kdg_hterm, zz + NINT * NW, lam_g + NG - NTERM, ht);
    for (o = 0; o < NX; o++)
        for (r = 0; r <= o; r++) Hnz[nz++] = ht[r + NX * o];
}

/* ---- the CasADi external interface ---- */
#define EXPORT CASADI_SYMBOL_EXPORT
#define WORK_FN(name)                                                                          \
    EXPORT int name##_work(casadi_int *sz_arg, casadi_int *sz_res, casadi_int *sz_iw, casadi_int *sz_w) \
    {                                                                                          \
        *sz_arg = 4; *sz_res = 2; *sz_iw = 0; *sz_w = 0; return 0;                            \
    }

static const casadi_int sp_x[3] = {NZ, 1, 1}, sp_p[3] = {NP, 1, 1}, sp_g[3] = {NG, 1, 1};
static const casadi_int sp_1[3] = {1, 1, 1};
static const double kdg_zeros[NG + NZ] = {0};

WORK_FN(kdg_nlp_g)
EXPORT casadi_int kdg_nlp_g_n_in(void) { return 2; }
EXPORT casadi_int kdg_nlp_g_n_out(void) { return 1; }
EXPORT const casadi_int *kdg_nlp_g_sparsity_in(casadi_int i) { return i == 0 ? sp_x : sp_p; }
EXPORT const casadi_int *kdg_nlp_g_sparsity_out(casadi_int i) { (void)i; return sp_g; }
EXPORT int kdg_nlp_g(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem)
{
    (void)iw; (void)w; (void)mem;
    if (res[0]) eval_g(arg[0] ? arg[0] : kdg_zeros, arg[1] ? arg[1] : kdg_zeros, res[0]);
    return 0;
}

WORK_FN(kdg_nlp_jac_g)
EXPORT casadi_int kdg_nlp_jac_g_n_in(void) { return 2; }
EXPORT casadi_int kdg_nlp_jac_g_n_out(void) { return 2; }
EXPORT const casadi_int *kdg_nlp_jac_g_sparsity_in(casadi_int i) { return i == 0 ? sp_x : sp_p; }
EXPORT const casadi_int *kdg_nlp_jac_g_sparsity_out(casadi_int i) { return i == 0 ? sp_g : kdg_sp_jac; }
EXPORT int kdg_nlp_jac_g(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem)
{
    const double *zz = arg[0] ? arg[0] : kdg_zeros, *p = arg[1] ? arg[1] : kdg_zeros;
    (void)iw; (void)w; (void)mem;
    if (res[1]) eval_jac(zz, p, res[1]);
    if (res[0]) eval_g(zz, p, res[0]);
    return 0;
}

WORK_FN(kdg_nlp_hess)
EXPORT casadi_int kdg_nlp_hess_n_in(void) { return 4; }
EXPORT casadi_int kdg_nlp_hess_n_out(void) { return 1; }
EXPORT const casadi_int *kdg_nlp_hess_sparsity_in(casadi_int i)
{
    return i == 0 ? sp_x : i == 1 ? sp_p : i == 2 ? sp_1 : sp_g;
}
EXPORT const casadi_int *kdg_nlp_hess_sparsity_out(casadi_int i) { (void)i; return kdg_sp_hess; }
EXPORT int kdg_nlp_hess(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem)
{
    (void)iw; (void)w; (void)mem;
    if (res[0]) eval_hess(arg[0] ? arg[0] : kdg_zeros, arg[1] ? arg[1] : kdg_zeros, arg[2] ? arg[2][0] : 0.0,
                          arg[3] ? arg[3] : kdg_zeros, res[0]);
    return 0;
}

/* jac_kdg_nlp_g: looked up by name by nlpsol's multiplier post-processing (dg/dx, dg/dp) */
WORK_FN(jac_kdg_nlp_g)
EXPORT casadi_int jac_kdg_nlp_g_n_in(void) { return 3; }
EXPORT casadi_int jac_kdg_nlp_g_n_out(void) { return 2; }
EXPORT const casadi_int *jac_kdg_nlp_g_sparsity_in(casadi_int i) { return i == 0 ? sp_x : i == 1 ? sp_p : sp_g; }
EXPORT const casadi_int *jac_kdg_nlp_g_sparsity_out(casadi_int i) { return i == 0 ? kdg_sp_jac : kdg_sp_jp; }
EXPORT int jac_kdg_nlp_g(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem)
{
    const double *zz = arg[0] ? arg[0] : kdg_zeros, *p = arg[1] ? arg[1] : kdg_zeros;
    int r;
    (void)iw; (void)w; (void)mem;
    if (res[0]) eval_jac(zz, p, res[0]);
    if (res[1]) for (r = 0; r < NP; r++) res[1][r] = -1.0;
    return 0;
}

/* ---- plain C entry points (ctypes): the tracking MPC's linearisation and the robot's
 * dynamics for a controller's observer ---- */

/* For every interval k: x_k = x0 (k = 0) or X[k-1], u_k = U[k] + d. F[k] (NX): the interval's
 * end; AB[k] (NX x NW, row-major): [dF/dx dF/du]; XI[k] (NIN), AXI[k] (NIN x NW): the inner
 * substep states and their Jacobians. */
EXPORT void kdg_linearise(const double *x0, const double *X, const double *U, const double *d, double *F,
                          double *AB, double *XI, double *AXI)
{
    int k, r, o;
    chain_t c;
    double u[NQ];
    for (k = 0; k < NINT; k++) {
        const double *xk = k == 0 ? x0 : X + (k - 1) * NX;
        for (r = 0; r < NQ; r++) u[r] = U[k * NQ + r] + d[r];
        chain(xk, u, &c, 1);
        memcpy(F + k * NX, c.xo[NSUB - 1], NX * sizeof(double));
        memcpy(AB + (long)k * NX * NW, c.dxo[NSUB - 1], NX * NW * sizeof(double));
        for (o = 0; o < NSUB - 1 && NIN > 0; o++) {
            memcpy(XI + k * NIN + o * NX, c.xo[o], NX * sizeof(double));
            memcpy(AXI + (long)k * NIN * NW + (long)o * NX * NW, c.dxo[o], NX * NW * sizeof(double));
        }
    }
}

/* the interval's end from x with u (values only) */
EXPORT void kdg_step(const double *x, const double *u, double *xn)
{
    chain_t c;
    chain(x, u, &c, 0);
    memcpy(xn, c.xo[NSUB - 1], NX * sizeof(double));
}

/* For every interval k (x_k = x0 for k = 0, else X[k-1]; u_k = U[k] + d): H[k] (NW x NW,
 * row-major, symmetric) = the Hessian over (x_k, u_k) of sum_o MU[k][o]' x_o, MU[k] (NSUB x NX)
 * the multipliers of the substep ends (the last: the interval's end F). */
EXPORT void kdg_hessians(const double *x0, const double *X, const double *U, const double *d, const double *MU,
                         double *H)
{
    int k, r, col;
    chain_t c;
    double u[NQ], mu[NSUB][NX];
    for (k = 0; k < NINT; k++) {
        const double *xk = k == 0 ? x0 : X + (k - 1) * NX;
        double *Hk = H + (long)k * NW * NW;
        for (r = 0; r < NQ; r++) u[r] = U[k * NQ + r] + d[r];
        memcpy(mu, MU + (long)k * NSUB * NX, sizeof mu);
        chain(xk, u, &c, 1);
        interval_hessian(&c, (const double (*)[NX])mu, Hk);
        for (r = 0; r < NW; r++)
            for (col = 0; col < r; col++) Hk[r * NW + col] = Hk[col * NW + r];
    }
}

/* the terminal rows at xN: t = (flange position - goal, qd), their Jacobian J (NTERM x NX,
 * row-major) and the Hessian H (NX x NX, row-major) of lt' t */
EXPORT void kdg_terminal(const double *xN, const double *goal, const double *lt, double *t, double *J, double *H)
{
    double jt[NTERM * NX], ht[NX * NX];
    int r, col;
    call_helper(kdg_term, xN, goal, t);
    call_helper(kdg_jterm, xN, goal, jt);
    call_helper(kdg_hterm, xN, lt, ht);
    for (r = 0; r < NTERM; r++)
        for (col = 0; col < NX; col++) J[r * NX + col] = jt[r + NTERM * col];
    for (r = 0; r < NX; r++)
        for (col = 0; col < NX; col++) H[r * NX + col] = ht[r + NX * col];
}

EXPORT void kdg_fd(const double *q, const double *qd, const double *tau, double *qdd) { KDG_FD(q, qd, tau, qdd); }
EXPORT void kdg_tau(const double *q, const double *qd, const double *qdd, double *tau) { KDG_TAU(q, qd, qdd, tau); }
EXPORT int kdg_sizes(int *out)
{
    out[0] = NDOF; out[1] = NINT; out[2] = NSTAGE; out[3] = NSUB; out[4] = NIN; out[5] = NZ; out[6] = NG;
    return 0;
}

/* The fd_rk4 reach NLP's constraints, their Jacobian and the Hessian of its Lagrangian as three
 * CasADi external functions (examples/ocp_fd_stages.py, native=True): one file for the whole
 * horizon, with the forward chain of every interval (its four RK4 stage states, the analytic
 * fd_derivatives there and the chained Jacobians) computed once per point z and kept for the
 * Hessian, which IPOPT asks for at the same z as the Jacobian.
 *
 * Included by a glue file that ocp_fd_stages.py writes, after the robot's generated C (for
 * KDG_FD and KDG_FDD, row-major) and CasADi's code of the small helpers kdg_idh (the 21 x 21
 * Hessian of lam' tau(q, qd, qdd), dense), kdg_term, kdg_jterm (dense 10 x 14) and kdg_hterm
 * (dense 14 x 14), and the macros NDOF, NINT (intervals) and HSTEP (interval length).
 *
 * z = (x_0, u_0, ..., x_{N-1}, u_{N-1}, x_N), x = (q, qd), u = tau; p = (x_init, goal);
 * g = (gap_0, x_0 - x_init, gap_1, ..., gap_{N-1}, terminal), gap_k = x_{k+1} - F(x_k, u_k)
 * (examples/ocp_stages.py's order). The Hessian is the upper triangle, block diagonal.
 *
 * Not re-entrant: one cache (the last point's forward chain) per process. */
#include <stdlib.h>
#include <string.h>

#define NQ NDOF
#define NX (2 * NQ)
#define NW (3 * NQ)                  /* (x_k, u_k) */
#define NTERM (3 + NQ)
#define NZ (NINT * NW + NX)
#define NG (NINT * NX + NX + NTERM)
#define NP (NX + 3)

/* forward chain of one interval */
typedef struct {
    double y[4][NW];                 /* stage states (q_i, v_i, a_i) */
    double dq[4][NQ * NQ], dv[4][NQ * NQ], minv[4][NQ * NQ];  /* fd_derivatives, row-major */
    double dy[4][NW * NW];           /* d y_i / d w, row-major (rows: q, v, a) */
    double xn[NX];                   /* F(x_k, u_k) */
    double df[NX * NW];              /* d F / d w, row-major */
} chain_t;

static chain_t kdg_chain[NINT];
static double kdg_chain_z[NZ];
static int kdg_chain_ok = 0;         /* kdg_chain holds the derivatives at kdg_chain_z */
static double kdg_gap_z[NZ], kdg_gap[NINT][NX];
static int kdg_gap_ok = 0;           /* kdg_gap holds F at kdg_gap_z */

static const double kdg_c[4] = {0.0, HSTEP / 2, HSTEP / 2, HSTEP};

/* F(x, u) only: four forward dynamics */
static void rk4_gap(const double *x, const double *u, double *xn)
{
    double z[NX], k[NX], acc[NX];
    int i, r;
    memset(acc, 0, sizeof acc);
    for (i = 0; i < 4; i++) {
        for (r = 0; r < NX; r++) z[r] = i == 0 ? x[r] : x[r] + kdg_c[i] * k[r];
        for (r = 0; r < NQ; r++) k[r] = z[NQ + r];
        KDG_FD(z, z + NQ, u, k + NQ);
        for (r = 0; r < NX; r++) acc[r] += (i == 0 || i == 3 ? 1.0 : 2.0) * k[r];
    }
    for (r = 0; r < NX; r++) xn[r] = x[r] + HSTEP / 6 * acc[r];
}

/* the forward chain: stage states, fd_derivatives, d z_i / d w, F and dF/dw */
static void rk4_chain(const double *x, const double *u, chain_t *c)
{
    double z[NX], k[NX], acc[NX];
    double dz[NX * NW], dk[NX * NW];  /* d z_i / d w, d k_i / d w, row-major */
    int i, r, j, m;
    memset(acc, 0, sizeof acc);
    memset(c->df, 0, sizeof c->df);
    for (i = 0; i < 4; i++) {
        for (r = 0; r < NX; r++) z[r] = i == 0 ? x[r] : x[r] + kdg_c[i] * k[r];
        for (r = 0; r < NX; r++)
            for (j = 0; j < NW; j++)
                dz[r * NW + j] = (r == j ? 1.0 : 0.0) + (i == 0 ? 0.0 : kdg_c[i] * dk[r * NW + j]);
        for (r = 0; r < NQ; r++) k[r] = z[NQ + r];
        KDG_FD(z, z + NQ, u, k + NQ);
        KDG_FDD(z, z + NQ, u, c->dq[i], c->dv[i], c->minv[i]);
        /* d k_i = (d v_i, Dq d q_i + Dv d v_i + [0 Minv]) */
        memcpy(dk, dz + NQ * NW, NQ * NW * sizeof(double));
        for (r = 0; r < NQ; r++) {
            double *row = dk + (NQ + r) * NW;
            const double *Dq = c->dq[i] + r * NQ, *Dv = c->dv[i] + r * NQ;
            for (j = 0; j < NW; j++) row[j] = 0.0;
            for (m = 0; m < NQ; m++) {
                const double a = Dq[m], b = Dv[m];
                const double *zq = dz + m * NW, *zv = dz + (NQ + m) * NW;
                for (j = 0; j < NW; j++) row[j] += a * zq[j] + b * zv[j];
            }
            for (j = 0; j < NQ; j++) row[NX + j] += c->minv[i][r * NQ + j];
        }
        for (r = 0; r < NX; r++) c->y[i][r] = z[r];
        for (r = 0; r < NQ; r++) c->y[i][NX + r] = k[NQ + r];
        memcpy(c->dy[i], dz, NX * NW * sizeof(double));
        memcpy(c->dy[i] + NX * NW, dk + NQ * NW, NQ * NW * sizeof(double));
        {
            const double w = i == 0 || i == 3 ? 1.0 : 2.0;
            for (r = 0; r < NX; r++) acc[r] += w * k[r];
            for (r = 0; r < NX * NW; r++) c->df[r] += w * dk[r];
        }
    }
    for (r = 0; r < NX; r++) c->xn[r] = x[r] + HSTEP / 6 * acc[r];
    for (r = 0; r < NX * NW; r++) c->df[r] *= HSTEP / 6;
    for (r = 0; r < NX; r++) c->df[r * NW + r] += 1.0;
}

static void ensure_gaps(const double *zz)
{
    int k;
    if (kdg_gap_ok && memcmp(zz, kdg_gap_z, sizeof kdg_gap_z) == 0) return;
    if (kdg_chain_ok && memcmp(zz, kdg_chain_z, sizeof kdg_chain_z) == 0) {
        for (k = 0; k < NINT; k++) memcpy(kdg_gap[k], kdg_chain[k].xn, sizeof kdg_gap[k]);
    } else {
        for (k = 0; k < NINT; k++) rk4_gap(zz + k * NW, zz + k * NW + NX, kdg_gap[k]);
    }
    memcpy(kdg_gap_z, zz, sizeof kdg_gap_z);
    kdg_gap_ok = 1;
}

static void ensure_chain(const double *zz)
{
    int k;
    if (kdg_chain_ok && memcmp(zz, kdg_chain_z, sizeof kdg_chain_z) == 0) return;
    for (k = 0; k < NINT; k++) rk4_chain(zz + k * NW, zz + k * NW + NX, &kdg_chain[k]);
    memcpy(kdg_chain_z, zz, sizeof kdg_chain_z);
    kdg_chain_ok = 1;
}

/* CasADi-generated helpers, called through their generic interface */
static casadi_real kdg_wbuf[KDG_SZW];
static casadi_int kdg_iwbuf[KDG_SZIW];
static const double kdg_zeros[NG + NZ];

static void call_helper(int (*f)(const casadi_real **, casadi_real **, casadi_int *, casadi_real *, int),
                        const double *a0, const double *a1, double *r0)
{
    const casadi_real *arg[8];
    casadi_real *res[8];
    arg[0] = a0;
    arg[1] = a1;
    res[0] = r0;
    f(arg, res, kdg_iwbuf, kdg_wbuf, 0);
}

static void eval_g(const double *zz, const double *p, double *g)
{
    int k, r;
    double term[NTERM];
    ensure_gaps(zz);
    for (k = 0; k < NINT; k++) {
        double *gk = g + (k == 0 ? 0 : NX + k * NX);
        const double *x1 = zz + (k + 1) * NW;
        for (r = 0; r < NX; r++) gk[r] = x1[r] - kdg_gap[k][r];
    }
    for (r = 0; r < NX; r++) g[NX + r] = zz[r] - p[r];
    call_helper(kdg_term, zz + NINT * NW, p + NX, term);
    memcpy(g + NG - NTERM, term, sizeof term);
}

/* ---- sparsity (CasADi compressed column format: nrow, ncol, colind[ncol + 1], row[nnz]) ---- */
#define JNNZ (NINT * NW * NX + NX + (NINT - 1) * NX + NX + NX * NTERM)
#define HNNZ (NINT * NW * (NW + 1) / 2 + NX * (NX + 1) / 2)
static casadi_int sp_jac[2 + NZ + 1 + JNNZ], sp_hess[2 + NZ + 1 + HNNZ];
static const casadi_int sp_x[3] = {NZ, 1, 1}, sp_p[3] = {NP, 1, 1}, sp_g[3] = {NG, 1, 1};
static const casadi_int sp_1[3] = {1, 1, 1};
static int sp_ok = 0;

static casadi_int gap_row(int k) { return k == 0 ? 0 : NX + (casadi_int)k * NX; }

static void build_sparsity(void)
{
    casadi_int *ci = sp_jac + 2, *ri = sp_jac + 3 + NZ, nz = 0;
    int col, k, o, r;
    if (sp_ok) return;
    sp_jac[0] = NG;
    sp_jac[1] = NZ;
    for (col = 0; col < NZ; col++) {
        ci[col] = nz;
        k = col / NW;
        o = col % NW;
        if (k < NINT) {
            if (o < NX && k >= 1) ri[nz++] = gap_row(k - 1) + o;
            for (r = 0; r < NX; r++) ri[nz++] = gap_row(k) + r;
            if (o < NX && k == 0) ri[nz++] = NX + o;
        } else {
            ri[nz++] = gap_row(NINT - 1) + o;
            for (r = 0; r < NTERM; r++) ri[nz++] = NG - NTERM + r;
        }
    }
    ci[NZ] = nz;
    ci = sp_hess + 2;
    ri = sp_hess + 3 + NZ;
    nz = 0;
    sp_hess[0] = NZ;
    sp_hess[1] = NZ;
    for (col = 0; col < NZ; col++) {
        ci[col] = nz;
        k = col / NW;
        o = col % NW;
        for (r = 0; r <= o; r++) ri[nz++] = (casadi_int)k * NW + r;
    }
    ci[NZ] = nz;
    sp_ok = 1;
}

static void eval_jac(const double *zz, const double *p, double *J)
{
    double jt[NTERM * NX];
    int col, k, o, r;
    casadi_int nz = 0;
    (void)p;
    ensure_chain(zz);
    call_helper(kdg_jterm, zz + NINT * NW, p + NX, jt);     /* dense, column-major */
    for (col = 0; col < NZ; col++) {
        k = col / NW;
        o = col % NW;
        if (k < NINT) {
            const double *df = kdg_chain[k].df;
            if (o < NX && k >= 1) J[nz++] = 1.0;
            for (r = 0; r < NX; r++) J[nz++] = -df[r * NW + o];
            if (o < NX && k == 0) J[nz++] = 1.0;
        } else {
            J[nz++] = 1.0;
            for (r = 0; r < NTERM; r++) J[nz++] = jt[r + NTERM * o];
        }
    }
}

/* upper triangle of the Hessian of lam_f f + lam_g' g, block by block */
static void eval_hess(const double *zz, const double *p, double lam_f, const double *lam_g, double *Hnz)
{
    const double h = HSTEP;
    double Hw[NW * NW], Hid[NW * NW], ht[NX * NX];
    double T[NQ * NW], U[NQ * NW], W[NQ * NW];
    double b[4][NQ], rho[4][NQ], lam[4][NQ];
    int k, i, j, r, m, o;
    casadi_int nz = 0;
    (void)p;
    ensure_chain(zz);
    for (k = 0; k < NINT; k++) {
        const chain_t *c = &kdg_chain[k];
        const double *lk = lam_g + gap_row(k);
        /* mu = -lam (the gap is x_{k+1} - F); b = -F_a' mu */
        for (r = 0; r < NQ; r++) {
            const double mq = -lk[r], mv = -lk[NQ + r];
            b[0][r] = -(h * h / 6 * mq + h / 6 * mv);
            b[1][r] = -(h * h / 6 * mq + h / 3 * mv);
            b[2][r] = -(h * h / 6 * mq + h / 3 * mv);
            b[3][r] = -(h / 6 * mv);
        }
        /* back substitution R_a' lam = b (examples/ocp_fd_stages.py rk4_lagrangian_hessian) */
        for (i = 3; i >= 0; i--) {
            for (r = 0; r < NQ; r++) rho[i][r] = b[i][r];
#define ADD_T(coef, D, j)                                                             \
            for (r = 0; r < NQ; r++)                                                  \
                for (m = 0; m < NQ; m++) rho[i][r] += (coef) * c->D[j][m * NQ + r] * rho[j][m];
            if (i == 2) { ADD_T(h, dv, 3) }
            if (i == 1) { ADD_T(h * h / 2, dq, 3) ADD_T(h / 2, dv, 2) }
            if (i == 0) { ADD_T(h * h / 4, dq, 2) ADD_T(h / 2, dv, 1) }
#undef ADD_T
            for (r = 0; r < NQ; r++) {
                double s = 0.0;
                for (m = 0; m < NQ; m++) s += c->minv[i][r * NQ + m] * rho[i][m];
                lam[i][r] = s;
            }
        }
        memset(Hw, 0, sizeof Hw);
        for (i = 0; i < 4; i++) {
            const double *dY = c->dy[i];
            const double *dQ = dY, *dV = dY + NQ * NW, *dA = dY + NX * NW;
            call_helper(kdg_idh, c->y[i], lam[i], Hid);       /* symmetric, dense */
            /* blocks of Hid (col-major = row-major, symmetric): qq, qv, qa, vv; aa = va = 0 */
            for (r = 0; r < NQ; r++) {
                double *t = T + r * NW, *u = U + r * NW, *w = W + r * NW;
                for (j = 0; j < NW; j++) t[j] = u[j] = w[j] = 0.0;
                for (m = 0; m < NQ; m++) {
                    const double hqq = Hid[r * NW + m], hqv = Hid[r * NW + NQ + m], hqa = Hid[r * NW + NX + m];
                    const double hvq = Hid[(NQ + r) * NW + m], hvv = Hid[(NQ + r) * NW + NQ + m];
                    const double haq = Hid[(NX + r) * NW + m];
                    const double *q_ = dQ + m * NW, *v_ = dV + m * NW, *a_ = dA + m * NW;
                    for (j = 0; j < NW; j++) {
                        t[j] += hqq * q_[j] + hqv * v_[j] + hqa * a_[j];
                        u[j] += hvq * q_[j] + hvv * v_[j];
                        w[j] += haq * q_[j];
                    }
                }
            }
            /* Hw += dQ' T + dV' U + dA' W (upper triangle: row a <= column j) */
            for (m = 0; m < NQ; m++) {
                const double *q_ = dQ + m * NW, *v_ = dV + m * NW, *a_ = dA + m * NW;
                const double *t = T + m * NW, *u = U + m * NW, *w = W + m * NW;
                for (o = 0; o < NW; o++) {
                    const double qa = q_[o], va = v_[o], aa = a_[o];
                    double *hr = Hw + o * NW;
                    for (j = o; j < NW; j++) hr[j] += qa * t[j] + va * u[j] + aa * w[j];
                }
            }
        }
        for (r = 0; r < NQ; r++) Hw[(NX + r) * NW + NX + r] += 2 * h * lam_f;
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
    }                                                                                          \
    EXPORT int name##_checkout(void) { return 0; }                                             \
    EXPORT void name##_release(int mem) { (void)mem; }                                         \
    EXPORT void name##_incref(void) {}                                                         \
    EXPORT void name##_decref(void) {}

WORK_FN(fdnlp_g)
WORK_FN(fdnlp_jac_g)
WORK_FN(fdnlp_hess)

EXPORT casadi_int fdnlp_g_n_in(void) { return 2; }
EXPORT casadi_int fdnlp_g_n_out(void) { return 1; }
EXPORT const casadi_int *fdnlp_g_sparsity_in(casadi_int i) { return i == 0 ? sp_x : sp_p; }
EXPORT const casadi_int *fdnlp_g_sparsity_out(casadi_int i) { (void)i; return sp_g; }
EXPORT int fdnlp_g(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem)
{
    (void)iw; (void)w; (void)mem;
    if (res[0]) eval_g(arg[0] ? arg[0] : kdg_zeros, arg[1] ? arg[1] : kdg_zeros, res[0]);
    return 0;
}

EXPORT casadi_int fdnlp_jac_g_n_in(void) { return 2; }
EXPORT casadi_int fdnlp_jac_g_n_out(void) { return 2; }
EXPORT const casadi_int *fdnlp_jac_g_sparsity_in(casadi_int i) { return i == 0 ? sp_x : sp_p; }
EXPORT const casadi_int *fdnlp_jac_g_sparsity_out(casadi_int i)
{
    build_sparsity();
    return i == 0 ? sp_g : sp_jac;
}
EXPORT int fdnlp_jac_g(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem)
{
    const double *zz = arg[0] ? arg[0] : kdg_zeros, *p = arg[1] ? arg[1] : kdg_zeros;
    (void)iw; (void)w; (void)mem;
    if (res[1]) eval_jac(zz, p, res[1]);
    if (res[0]) eval_g(zz, p, res[0]);
    return 0;
}

EXPORT casadi_int fdnlp_hess_n_in(void) { return 4; }
EXPORT casadi_int fdnlp_hess_n_out(void) { return 1; }
EXPORT const casadi_int *fdnlp_hess_sparsity_in(casadi_int i)
{
    return i == 0 ? sp_x : i == 1 ? sp_p : i == 2 ? sp_1 : sp_g;
}
EXPORT const casadi_int *fdnlp_hess_sparsity_out(casadi_int i)
{
    (void)i;
    build_sparsity();
    return sp_hess;
}
EXPORT int fdnlp_hess(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem)
{
    (void)iw; (void)w; (void)mem;
    if (res[0]) eval_hess(arg[0] ? arg[0] : kdg_zeros, arg[1] ? arg[1] : kdg_zeros, arg[2] ? arg[2][0] : 0.0,
                          arg[3] ? arg[3] : kdg_zeros, res[0]);
    return 0;
}

/* jac_fdnlp_g: CasADi's derivative of fdnlp_g (looked up by name; nlpsol's multiplier
 * post-processing differentiates g): inputs (x, p, g), outputs (dg/dx, dg/dp) */
static casadi_int sp_jp[2 + NP + 1 + NX + 3];
static int sp_jp_ok = 0;

static void build_sparsity_p(void)
{
    casadi_int *ci = sp_jp + 2, *ri = sp_jp + 3 + NP, nz = 0;
    int col;
    if (sp_jp_ok) return;
    sp_jp[0] = NG;
    sp_jp[1] = NP;
    for (col = 0; col < NP; col++) {
        ci[col] = nz;
        ri[nz++] = col < NX ? NX + col : NG - NTERM + (col - NX);   /* x_0 - x_init; position - goal */
    }
    ci[NP] = nz;
    sp_jp_ok = 1;
}

WORK_FN(jac_fdnlp_g)
EXPORT casadi_int jac_fdnlp_g_n_in(void) { return 3; }
EXPORT casadi_int jac_fdnlp_g_n_out(void) { return 2; }
EXPORT const casadi_int *jac_fdnlp_g_sparsity_in(casadi_int i) { return i == 0 ? sp_x : i == 1 ? sp_p : sp_g; }
EXPORT const casadi_int *jac_fdnlp_g_sparsity_out(casadi_int i)
{
    build_sparsity();
    build_sparsity_p();
    return i == 0 ? sp_jac : sp_jp;
}
EXPORT int jac_fdnlp_g(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem)
{
    const double *zz = arg[0] ? arg[0] : kdg_zeros, *p = arg[1] ? arg[1] : kdg_zeros;
    int r;
    (void)iw; (void)w; (void)mem;
    if (res[0]) eval_jac(zz, p, res[0]);
    if (res[1]) for (r = 0; r < NP; r++) res[1][r] = -1.0;
    return 0;
}

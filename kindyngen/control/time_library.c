/* The time-optimal point-to-point NLP's constraints, their Jacobian and the Hessian of its
 * Lagrangian in C: one library per robot, horizon and integrator, written by
 * kindyngen/control/native.py (time_optimal_library) over the robot's generated fd,
 * fd_derivatives and the CasADi-generated Hessian of m' tau (kdg_idh).
 *
 * The NLP (kindyngen/control/time_optimal.py): V = (T, vec X, vec U), X = [x_0 .. x_N] (2n x
 * N + 1, column-major), U = [u_0 .. u_{N-1}]; h = T / N; rows: the gaps c_k - x_{k+1} of every
 * interval (c_k the integrator's end from x_k under u_k over h), then the inner substep states of
 * every interval (NIN per interval); p = (c_1 .. c_n): the cost f = T + h sum_k sum_j c_j u_kj^2.
 *
 * Defined by the glue: NDOF, NINT, NSTAGE, NSUB, NIN, KDG_FD, KDG_FDD, the stage tables of the
 * integrator for h = 1 (kdg_gq, kdg_aq, kdg_bv, kdg_ogq, kdg_oaq, kdg_obv: stage states and
 * substep ends as linear forms of (q, h v, h^2 a_0.., h a_0..)), kdg_idh, and the sparsity tables
 * kdg_sp_jac, kdg_sp_hess, kdg_sp_jp.
 *
 * The interval's variables w = (x, u, h): every stage state is q_i = q + h gq_i v + h^2 sum_j
 * aq_ij a_j, v_i = v + h sum_j bv_ij a_j, with the stage accelerations a_j = fd(q_j, v_j, u); the
 * sensitivities are chained forward from fd_derivatives (no AD of the dynamics). The Hessian of
 * the interval's Lagrangian is reduced from the one with the stage accelerations as unknowns
 * tied by r_i = tau(q_i, v_i, a_i) - u = 0 (the implicit function theorem): with the stage
 * multipliers lam by back substitution through the mass matrices, sum_i dY_i' Hid(y_i, lam_i)
 * dY_i plus the terms of h, which multiplies v and a in the stage states (their second
 * derivatives in h, v and a, weighted by lam_i' dtau/dq = -Dq_i' M_i lam_i and lam_i' dtau/dv)
 * and in the substep ends (weighted by their own multipliers).
 *
 * Re-entrant: no globals but constant tables, no allocation. */
#include <string.h>

#define NQ NDOF
#define NX (2 * NQ)
#define NW (3 * NQ)                 /* (x, u) */
#define NW1 (NW + 1)                /* (x, u, h) */
#define NV (1 + NX * (NINT + 1) + NQ * NINT)
#define NG (NINT * NX + NINT * NIN)
#define IH NW                       /* the column of h in an interval's w */

typedef struct {
    double y[NSTAGE][NW];                 /* stage states (q_i, v_i, a_i) */
    double dq[NSTAGE][NQ * NQ], dv[NSTAGE][NQ * NQ], minv[NSTAGE][NQ * NQ];  /* fd_derivatives */
    double dy[NSTAGE][NW * NW1];          /* d y_i / d w, row-major (rows q, v, a) */
    double xo[NSUB][NX];                  /* ends of substeps 1..M (the last: the interval's end) */
    double dxo[NSUB][NX * NW1];           /* their Jacobians, row-major */
} tchain_t;

/* values (derivs = 0) or values and first derivatives (derivs = 1) of one interval */
static void tchain(const double *x, const double *u, double h, tchain_t *c, int derivs)
{
    double a[NSTAGE][NQ];
    const double h2 = h * h;
    int i, j, r, col, m, o;
    for (i = 0; i < NSTAGE; i++) {
        double *q = c->y[i], *v = c->y[i] + NQ;
        for (r = 0; r < NQ; r++) {
            double sq = x[r] + h * kdg_gq[i] * x[NQ + r], sv = x[NQ + r];
            for (j = 0; j < i; j++) {
                if (kdg_aq[i][j] != 0.0) sq += h2 * kdg_aq[i][j] * a[j][r];
                if (kdg_bv[i][j] != 0.0) sv += h * kdg_bv[i][j] * a[j][r];
            }
            q[r] = sq;
            v[r] = sv;
        }
        KDG_FD(q, v, u, a[i]);
        memcpy(c->y[i] + NX, a[i], sizeof a[i]);
        if (derivs) {
            double *dY = c->dy[i];
            double *dQ = dY, *dV = dY + NQ * NW1, *dA = dY + NX * NW1;
            KDG_FDD(q, v, u, c->dq[i], c->dv[i], c->minv[i]);
            memset(dQ, 0, 2 * NQ * NW1 * sizeof(double));
            for (r = 0; r < NQ; r++) {
                double eh_q = kdg_gq[i] * x[NQ + r], eh_v = 0.0;
                dQ[r * NW1 + r] = 1.0;
                dQ[r * NW1 + NQ + r] = h * kdg_gq[i];
                dV[r * NW1 + NQ + r] = 1.0;
                for (j = 0; j < i; j++) {
                    eh_q += 2 * h * kdg_aq[i][j] * a[j][r];
                    eh_v += kdg_bv[i][j] * a[j][r];
                }
                dQ[r * NW1 + IH] = eh_q;
                dV[r * NW1 + IH] = eh_v;
            }
            for (j = 0; j < i; j++) {
                const double ca = h2 * kdg_aq[i][j], cb = h * kdg_bv[i][j];
                const double *dAj = c->dy[j] + NX * NW1;
                if (ca != 0.0) for (col = 0; col < NQ * NW1; col++) dQ[col] += ca * dAj[col];
                if (cb != 0.0) for (col = 0; col < NQ * NW1; col++) dV[col] += cb * dAj[col];
            }
            /* da_i = Dq dq_i + Dv dv_i + [0 0 Minv 0] */
            for (r = 0; r < NQ; r++) {
                double *row = dA + r * NW1;
                const double *Dq = c->dq[i] + r * NQ, *Dv = c->dv[i] + r * NQ;
                for (col = 0; col < NW1; col++) row[col] = 0.0;
                for (m = 0; m < NQ; m++) {
                    const double p = Dq[m], s = Dv[m];
                    const double *zq = dQ + m * NW1, *zv = dV + m * NW1;
                    for (col = 0; col < NW1; col++) row[col] += p * zq[col] + s * zv[col];
                }
                for (col = 0; col < NQ; col++) row[NX + col] += c->minv[i][r * NQ + col];
            }
        }
    }
    for (o = 0; o < NSUB; o++) {
        for (r = 0; r < NQ; r++) {
            double sq = x[r] + h * kdg_ogq[o] * x[NQ + r], sv = x[NQ + r];
            for (j = 0; j < NSTAGE; j++) {
                if (kdg_oaq[o][j] != 0.0) sq += h2 * kdg_oaq[o][j] * a[j][r];
                if (kdg_obv[o][j] != 0.0) sv += h * kdg_obv[o][j] * a[j][r];
            }
            c->xo[o][r] = sq;
            c->xo[o][NQ + r] = sv;
        }
        if (derivs) {
            double *D = c->dxo[o];
            memset(D, 0, NX * NW1 * sizeof(double));
            for (r = 0; r < NQ; r++) {
                double eh_q = kdg_ogq[o] * x[NQ + r], eh_v = 0.0;
                D[r * NW1 + r] = 1.0;
                D[r * NW1 + NQ + r] = h * kdg_ogq[o];
                D[(NQ + r) * NW1 + NQ + r] = 1.0;
                for (j = 0; j < NSTAGE; j++) {
                    eh_q += 2 * h * kdg_oaq[o][j] * a[j][r];
                    eh_v += kdg_obv[o][j] * a[j][r];
                }
                D[r * NW1 + IH] = eh_q;
                D[(NQ + r) * NW1 + IH] = eh_v;
            }
            for (j = 0; j < NSTAGE; j++) {
                const double ca = h2 * kdg_oaq[o][j], cb = h * kdg_obv[o][j];
                const double *dAj = c->dy[j] + NX * NW1;
                if (ca != 0.0) for (col = 0; col < NQ * NW1; col++) D[col] += ca * dAj[col];
                if (cb != 0.0) for (col = 0; col < NQ * NW1; col++) D[NQ * NW1 + col] += cb * dAj[col];
            }
        }
    }
}

static void call_idh(const double *y, const double *m, double *H)
{
    const casadi_real *arg[KDG_SZARG];
    casadi_real *res[KDG_SZRES];
    casadi_int iw[KDG_SZIW];
    casadi_real w[KDG_SZW];
    arg[0] = y;
    arg[1] = m;
    res[0] = H;
    kdg_idh(arg, res, iw, w, 0);
}

/* H (NW1 x NW1, full, row-major): the Hessian over w = (x, u, h) of sum_o mu[o]' x_o(w) */
static void tinterval_hessian(const tchain_t *c, const double *x, double h, const double mu[NSUB][NX], double *H)
{
    double Hid[NW * NW];
    double T[NQ * NW1], U[NQ * NW1], W[NQ * NW1];
    double b[NSTAGE][NQ], rho[NSTAGE][NQ], lam[NSTAGE][NQ], rq[NSTAGE][NQ], rv[NSTAGE][NQ];
    double hrow[NW1];
    const double h2 = h * h;
    int i, j, r, m, o, col;
    /* b = -F_a' mu over every substep end (the coefficients of a in the ends at this h) */
    for (i = 0; i < NSTAGE; i++)
        for (r = 0; r < NQ; r++) {
            double s = 0.0;
            for (o = 0; o < NSUB; o++) s += h2 * kdg_oaq[o][i] * mu[o][r] + h * kdg_obv[o][i] * mu[o][NQ + r];
            b[i][r] = -s;
        }
    /* back substitution R_a' lam = b: rho_i = b_i + sum_{j > i} (aq_ji Dq_j' + bv_ji Dv_j') rho_j,
     * lam_i = Minv_i rho_i; rq_i = lam_i' dtau/dq = -Dq_i' rho_i, rv_i = -Dv_i' rho_i */
    for (i = NSTAGE - 1; i >= 0; i--) {
        for (r = 0; r < NQ; r++) rho[i][r] = b[i][r];
        for (j = i + 1; j < NSTAGE; j++) {
            const double ca = h2 * kdg_aq[j][i], cb = h * kdg_bv[j][i];
            if (ca != 0.0)
                for (r = 0; r < NQ; r++) rho[i][r] -= ca * rq[j][r];
            if (cb != 0.0)
                for (r = 0; r < NQ; r++) rho[i][r] -= cb * rv[j][r];
        }
        for (r = 0; r < NQ; r++) {
            double s = 0.0, sq = 0.0, sv = 0.0;
            for (m = 0; m < NQ; m++) {
                s += c->minv[i][r * NQ + m] * rho[i][m];
                sq += c->dq[i][m * NQ + r] * rho[i][m];
                sv += c->dv[i][m * NQ + r] * rho[i][m];
            }
            lam[i][r] = s;
            rq[i][r] = -sq;
            rv[i][r] = -sv;
        }
    }
    memset(H, 0, NW1 * NW1 * sizeof(double));
    /* sum_i dY_i' Hid(y_i, lam_i) dY_i (upper triangle first) */
    for (i = 0; i < NSTAGE; i++) {
        const double *dY = c->dy[i];
        const double *dQ = dY, *dV = dY + NQ * NW1, *dA = dY + NX * NW1;
        call_idh(c->y[i], lam[i], Hid);
        for (r = 0; r < NQ; r++) {
            double *t = T + r * NW1, *u_ = U + r * NW1, *w = W + r * NW1;
            for (col = 0; col < NW1; col++) t[col] = u_[col] = w[col] = 0.0;
            for (m = 0; m < NQ; m++) {
                const double hqq = Hid[r * NW + m], hqv = Hid[r * NW + NQ + m], hqa = Hid[r * NW + NX + m];
                const double hvq = Hid[(NQ + r) * NW + m], hvv = Hid[(NQ + r) * NW + NQ + m];
                const double haq = Hid[(NX + r) * NW + m];
                const double *q_ = dQ + m * NW1, *v_ = dV + m * NW1, *a_ = dA + m * NW1;
                for (col = 0; col < NW1; col++) {
                    t[col] += hqq * q_[col] + hqv * v_[col] + hqa * a_[col];
                    u_[col] += hvq * q_[col] + hvv * v_[col];
                    w[col] += haq * q_[col];
                }
            }
        }
        for (m = 0; m < NQ; m++) {
            const double *q_ = dQ + m * NW1, *v_ = dV + m * NW1, *a_ = dA + m * NW1;
            const double *t = T + m * NW1, *u_ = U + m * NW1, *w = W + m * NW1;
            for (o = 0; o < NW1; o++) {
                const double qa = q_[o], va = v_[o], aa = a_[o];
                double *hr = H + o * NW1;
                if (qa == 0.0 && va == 0.0 && aa == 0.0) continue;
                for (col = o; col < NW1; col++) hr[col] += qa * t[col] + va * u_[col] + aa * w[col];
            }
        }
    }
    for (r = 0; r < NW1; r++)
        for (col = 0; col < r; col++) H[r * NW1 + col] = H[col * NW1 + r];
    /* the terms of h: second derivatives of the stage states (weights rq_i, rv_i) and of the
     * substep ends (weights mu_o) in (h, v) and (h, a_j) and (h, h), projected: a row hrow added
     * to H's row and column of h, and the diagonal (h, h) */
    memset(hrow, 0, sizeof hrow);
    for (i = 0; i < NSTAGE; i++) {
        const double *wq = rq[i], *wv = rv[i];
        for (r = 0; r < NQ; r++) hrow[NQ + r] += kdg_gq[i] * wq[r];           /* d2 q_i / dh dv */
        for (j = 0; j < i; j++) {
            const double ca = kdg_aq[i][j], cb = kdg_bv[i][j];
            const double *dAj = c->dy[j] + NX * NW1, *aj = c->y[j] + NX;
            if (ca == 0.0 && cb == 0.0) continue;
            for (r = 0; r < NQ; r++) {
                const double f = 2 * h * ca * wq[r] + cb * wv[r];
                for (col = 0; col < NW1; col++) hrow[col] += f * dAj[r * NW1 + col];
                H[IH * NW1 + IH] += 2 * ca * wq[r] * aj[r];              /* d2 q_i / dh2 */
            }
        }
    }
    for (o = 0; o < NSUB; o++) {
        const double *wq = mu[o], *wv = mu[o] + NQ;
        for (r = 0; r < NQ; r++) hrow[NQ + r] += kdg_ogq[o] * wq[r];
        for (j = 0; j < NSTAGE; j++) {
            const double ca = kdg_oaq[o][j], cb = kdg_obv[o][j];
            const double *dAj = c->dy[j] + NX * NW1, *aj = c->y[j] + NX;
            if (ca == 0.0 && cb == 0.0) continue;
            for (r = 0; r < NQ; r++) {
                const double f = 2 * h * ca * wq[r] + cb * wv[r];
                for (col = 0; col < NW1; col++) hrow[col] += f * dAj[r * NW1 + col];
                H[IH * NW1 + IH] += 2 * ca * wq[r] * aj[r];
            }
        }
    }
    for (col = 0; col < NW1; col++) {
        H[IH * NW1 + col] += hrow[col];
        H[col * NW1 + IH] += hrow[col];
    }
    (void)x;
}

static double var_h(const double *V) { return V[0] / NINT; }
static const double *var_x(const double *V, int k) { return V + 1 + NX * k; }
static const double *var_u(const double *V, int k) { return V + 1 + NX * (NINT + 1) + NQ * k; }

static void eval_g(const double *V, double *g)
{
    int k, r, o;
    tchain_t c;
    const double h = var_h(V);
    for (k = 0; k < NINT; k++) {
        const double *x1 = var_x(V, k + 1);
        tchain(var_x(V, k), var_u(V, k), h, &c, 0);
        for (r = 0; r < NX; r++) g[k * NX + r] = c.xo[NSUB - 1][r] - x1[r];
        for (o = 0; o < NSUB - 1; o++)
            for (r = 0; r < NX; r++) g[NINT * NX + k * NIN + o * NX + r] = c.xo[o][r];
    }
}

/* where the nonzeros of a column of x_k (len: the -I of gap k-1, gap k's and inner rows) and of
 * a column of u_k start in the Jacobian (native.py TimeLayout.jacobian_pattern) */
static long xcol(int k, int col)
{
    const long len = k == 0 ? NX + NIN : k == NINT ? 1 : 1 + NX + NIN;
    const long before = k == 0 ? 0 : (NX + NIN) + (long)(k - 1) * (1 + NX + NIN);
    return NG + (long)NX * before + col * len;
}
static long ucol(int k, int col) { return NG + (long)NX * NINT * (NX + NIN + 1) + ((long)k * NQ + col) * (NX + NIN); }

/* the Jacobian's nonzeros in the order of kdg_sp_jac (and g, if given) */
static void eval_jac(const double *V, double *J, double *g)
{
    int k, r, o, col;
    long nz;
    tchain_t c;
    const double h = var_h(V);
    for (k = 0; k < NINT; k++) {
        const double *x1 = var_x(V, k + 1);
        tchain(var_x(V, k), var_u(V, k), h, &c, 1);
        /* the column of T: every row, d g / dh / N */
        for (r = 0; r < NX; r++) {
            J[k * NX + r] = c.dxo[NSUB - 1][r * NW1 + IH] / NINT;
            if (g) g[k * NX + r] = c.xo[NSUB - 1][r] - x1[r];
        }
        for (o = 0; o < NSUB - 1; o++)
            for (r = 0; r < NX; r++) {
                J[NINT * NX + k * NIN + o * NX + r] = c.dxo[o][r * NW1 + IH] / NINT;
                if (g) g[NINT * NX + k * NIN + o * NX + r] = c.xo[o][r];
            }
        for (col = 0; col < NW; col++) {
            nz = col < NX ? xcol(k, col) + (k > 0) : ucol(k, col - NX);
            for (r = 0; r < NX; r++) J[nz++] = c.dxo[NSUB - 1][r * NW1 + col];
            for (o = 0; o < NSUB - 1; o++)
                for (r = 0; r < NX; r++) J[nz++] = c.dxo[o][r * NW1 + col];
        }
        for (col = 0; col < NX; col++) J[xcol(k + 1, col)] = -1.0;     /* - x_{k+1} in gap k */
    }
}

/* upper triangle of the Hessian of lam_f f + lam_g' g, nonzeros in the order of kdg_sp_hess */
static void eval_hess(const double *V, const double *p, double lam_f, const double *lam_g, double *Hnz)
{
    double H[NW1 * NW1], mu[NSUB][NX];
    int k, r, o, col;
    long nz, unz;
    tchain_t c;
    const double h = var_h(V);
    const double n1 = 1.0 / NINT;
    Hnz[0] = 0.0;
    nz = 1;
    unz = 1 + (long)NINT * (NX + NX * (NX + 1) / 2);
    for (k = 0; k < NINT; k++) {
        const double *u = var_u(V, k);
        tchain(var_x(V, k), u, h, &c, 1);
        for (r = 0; r < NX; r++) mu[NSUB - 1][r] = lam_g[k * NX + r];
        for (o = 0; o < NSUB - 1; o++)
            for (r = 0; r < NX; r++) mu[o][r] = lam_g[NINT * NX + k * NIN + o * NX + r];
        tinterval_hessian(&c, var_x(V, k), h, (const double (*)[NX])mu, H);
        /* the cost h sum_j p_j u_j^2 */
        for (r = 0; r < NQ; r++) {
            H[(NX + r) * NW1 + NX + r] += 2 * lam_f * p[r] * h;
            H[(NX + r) * NW1 + IH] += 2 * lam_f * p[r] * u[r];
            H[IH * NW1 + NX + r] += 2 * lam_f * p[r] * u[r];
        }
        Hnz[0] += H[IH * NW1 + IH] * n1 * n1;
        /* columns x_k: the row of T, then x_k's rows up to the diagonal */
        for (col = 0; col < NX; col++) {
            Hnz[nz++] = H[IH * NW1 + col] * n1;
            for (r = 0; r <= col; r++) Hnz[nz++] = H[r * NW1 + col];
        }
        /* columns u_k (after all x columns): the row of T, x_k's rows, u_k's up to the diagonal */
        for (col = NX; col < NW; col++) {
            Hnz[unz++] = H[IH * NW1 + col] * n1;
            for (r = 0; r < NX; r++) Hnz[unz++] = H[r * NW1 + col];
            for (r = NX; r <= col; r++) Hnz[unz++] = H[r * NW1 + col];
        }
    }
}

/* ---- the CasADi external interface ---- */
#define EXPORT CASADI_SYMBOL_EXPORT
#define WORK_FN(name)                                                                          \
    EXPORT int name##_work(casadi_int *sz_arg, casadi_int *sz_res, casadi_int *sz_iw, casadi_int *sz_w) \
    {                                                                                          \
        *sz_arg = 4; *sz_res = 2; *sz_iw = 0; *sz_w = 0; return 0;                            \
    }

static const casadi_int sp_x[3] = {NV, 1, 1}, sp_p[3] = {NQ, 1, 1}, sp_g[3] = {NG, 1, 1};
static const casadi_int sp_1[3] = {1, 1, 1};
static const double kdg_zeros[NG + NV] = {0};

WORK_FN(topt_nlp_g)
EXPORT casadi_int topt_nlp_g_n_in(void) { return 2; }
EXPORT casadi_int topt_nlp_g_n_out(void) { return 1; }
EXPORT const casadi_int *topt_nlp_g_sparsity_in(casadi_int i) { return i == 0 ? sp_x : sp_p; }
EXPORT const casadi_int *topt_nlp_g_sparsity_out(casadi_int i) { (void)i; return sp_g; }
EXPORT int topt_nlp_g(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem)
{
    (void)iw; (void)w; (void)mem;
    if (res[0]) eval_g(arg[0] ? arg[0] : kdg_zeros, res[0]);
    return 0;
}

WORK_FN(topt_nlp_jac_g)
EXPORT casadi_int topt_nlp_jac_g_n_in(void) { return 2; }
EXPORT casadi_int topt_nlp_jac_g_n_out(void) { return 2; }
EXPORT const casadi_int *topt_nlp_jac_g_sparsity_in(casadi_int i) { return i == 0 ? sp_x : sp_p; }
EXPORT const casadi_int *topt_nlp_jac_g_sparsity_out(casadi_int i) { return i == 0 ? sp_g : kdg_sp_jac; }
EXPORT int topt_nlp_jac_g(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem)
{
    const double *V = arg[0] ? arg[0] : kdg_zeros;
    (void)iw; (void)w; (void)mem;
    if (res[1]) eval_jac(V, res[1], res[0]);
    else if (res[0]) eval_g(V, res[0]);
    return 0;
}

WORK_FN(topt_nlp_hess)
EXPORT casadi_int topt_nlp_hess_n_in(void) { return 4; }
EXPORT casadi_int topt_nlp_hess_n_out(void) { return 1; }
EXPORT const casadi_int *topt_nlp_hess_sparsity_in(casadi_int i)
{
    return i == 0 ? sp_x : i == 1 ? sp_p : i == 2 ? sp_1 : sp_g;
}
EXPORT const casadi_int *topt_nlp_hess_sparsity_out(casadi_int i) { (void)i; return kdg_sp_hess; }
EXPORT int topt_nlp_hess(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem)
{
    (void)iw; (void)w; (void)mem;
    if (res[0]) eval_hess(arg[0] ? arg[0] : kdg_zeros, arg[1] ? arg[1] : kdg_zeros, arg[2] ? arg[2][0] : 0.0,
                          arg[3] ? arg[3] : kdg_zeros, res[0]);
    return 0;
}

/* jac_topt_nlp_g: looked up by name by nlpsol's multiplier post-processing (dg/dx, dg/dp = 0) */
WORK_FN(jac_topt_nlp_g)
EXPORT casadi_int jac_topt_nlp_g_n_in(void) { return 3; }
EXPORT casadi_int jac_topt_nlp_g_n_out(void) { return 2; }
EXPORT const casadi_int *jac_topt_nlp_g_sparsity_in(casadi_int i) { return i == 0 ? sp_x : i == 1 ? sp_p : sp_g; }
EXPORT const casadi_int *jac_topt_nlp_g_sparsity_out(casadi_int i) { return i == 0 ? kdg_sp_jac : kdg_sp_jp; }
EXPORT int jac_topt_nlp_g(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem)
{
    (void)iw; (void)w; (void)mem;
    if (res[0]) eval_jac(arg[0] ? arg[0] : kdg_zeros, res[0], 0);
    return 0;
}

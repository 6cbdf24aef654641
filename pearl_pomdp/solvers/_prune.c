/* One prune of a set of alpha-vectors, in C: see pearl_pomdp/solvers/prune.py for what and why.
 *
 * Plain CPython C API and the buffer protocol (no numpy headers). Two entry points:
 *   prune(alphas, tol, points (tuple of arrays), random_budget, random_beliefs, deadline, kept_out, witness_out)
 *       -> (n, lps, lp_witnesses, lp_resolves, lp_failures)
 *   WitnessLP(S): add(alpha), solve(c) -> (delta, b): the LP of Lark's filter alone (tests).
 *
 * Legend (the names used below)
 *   K, S     number of vectors (rows of A) and of states; A[i*S + s] = alpha_i(s)
 *   tol      a vector must win by at least tol somewhere (prune.py's DEFAULT_TOL and its docstring)
 *   cand, C  indices left after duplicates and pointwise dominance (ascending), and their number
 *   kord, nk indices of the kept vectors in the order they were found (the LP's columns), and their number
 *   wit      wit[r*S + s]: witness belief of kord[r]
 *   alive    alive[i]: vector i still waits for its verdict in Lark's filter
 *   queue    Lark's filter's queue of candidates; a candidate whose witness went to another vector
 *            is appended again
 *
 * The witness LP (Lark's filter), solved in its dual form, which has m = S + 1 rows however many
 * vectors are kept (what HiGHS solved before):
 *   min t   s.t.   sum_k lambda_k alpha_k(s) + t - sigma_s = c(s)   (s < S),   sum_k lambda_k = 1,
 *           lambda >= 0, sigma >= 0, t free.
 * Its optimum is delta* = max_b c.b - max_k alpha_k.b, and the duals y of the state rows are the
 * optimal b (y[S] = -max_k alpha_k.b). Variables: id 0 = t, 1..S = sigma_{id-1}, S+1+k = lambda_k.
 *   head[p]  variable basic in row p;  pos[id]  its row, or -1 when nonbasic
 *   Binv     the basis inverse, m x m row-major (dense: m is small); xB = Binv rhs, the basic values
 *   y        row pos[0] of Binv (t's cost is 1, every other cost 0), so no extra solve for the duals
 *   d_j      reduced cost: sigma_s -> y[s], lambda_k -> -(alpha_k . y[0:S] + y[S])
 * Warm start: only rhs (= c) changes between candidates, so the basis stays dual feasible and the
 * dual simplex re-optimises; a newly kept vector is a new column, nonbasic at 0, so the basis stays
 * primal feasible and the primal simplex re-optimises. Harris's two-pass ratio tests with Bland's
 * rule after a run of degenerate pivots keep degenerate LPs from cycling; the inverse is refactored
 * (Gauss-Jordan, partial pivoting) every REFACTOR_EVERY pivots, and a failed LP is re-solved from a
 * fresh basis once before it counts as "no witness" (as pomdp-solve treats LP trouble).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define PRIMAL_TOL 1e-10 /* basic values >= -PRIMAL_TOL count as feasible (HiGHS was given 1e-10) */
#define DUAL_TOL 1e-10   /* reduced costs >= -DUAL_TOL count as optimal */
#define PIVOT_TOL 1e-7   /* smallest |entry| accepted as a pivot */
#define REFACTOR_EVERY 50
#define DEGENERATE_RUN 20 /* degenerate pivots in a row before switching to Bland's rule */

/* ------------------------------------------------------------------ the witness LP */
typedef struct {
    int S, m;
    int ncols, cap;      /* lambda columns in total, allocated */
    int nactive;         /* lambda columns in the problem; the rest wait for the primal simplex */
    const double **col;  /* col[k]: alpha_k, S values (its row-S entry is 1) */
    int *head, *pos;     /* [m], [1 + S + cap] */
    double *Binv, *xB, *rhs, *u, *rho, *B; /* [m*m], [m], [m], [m], [m], [m*m] scratch */
    int *rj;             /* [1 + S + cap] the dual ratio test's candidates (j, alpha_rj, d_j): */
    double *ra, *rd;     /* computed once, read by both of Harris's passes */
    int has_basis, since_refactor, bland;
    long iterations;     /* pivots, in total */
} LP;

static void lp_free(LP *lp) {
    free(lp->col); free(lp->head); free(lp->pos); free(lp->Binv); free(lp->xB); free(lp->rhs);
    free(lp->u); free(lp->rho); free(lp->B); free(lp->rj); free(lp->ra); free(lp->rd);
    memset(lp, 0, sizeof(*lp));
}

static int lp_init(LP *lp, int S, int cap) {
    memset(lp, 0, sizeof(*lp));
    int m = S + 1;
    lp->S = S; lp->m = m; lp->cap = cap < 4 ? 4 : cap;
    lp->col = malloc(sizeof(double *) * lp->cap);
    lp->head = malloc(sizeof(int) * m);
    lp->pos = malloc(sizeof(int) * (1 + S + lp->cap));
    lp->Binv = malloc(sizeof(double) * m * m);
    lp->B = malloc(sizeof(double) * m * m);
    lp->xB = malloc(sizeof(double) * m);
    lp->rhs = malloc(sizeof(double) * m);
    lp->u = malloc(sizeof(double) * m);
    lp->rho = malloc(sizeof(double) * m);
    lp->rj = malloc(sizeof(int) * (1 + S + lp->cap));
    lp->ra = malloc(sizeof(double) * (1 + S + lp->cap));
    lp->rd = malloc(sizeof(double) * (1 + S + lp->cap));
    if (!lp->col || !lp->head || !lp->pos || !lp->Binv || !lp->B || !lp->xB || !lp->rhs || !lp->u || !lp->rho
        || !lp->rj || !lp->ra || !lp->rd) {
        lp_free(lp);
        return -1;
    }
    for (int j = 0; j < 1 + S + lp->cap; j++) lp->pos[j] = -1;
    return 0;
}

static int lp_add(LP *lp, const double *alpha) {
    if (lp->ncols == lp->cap) {
        int cap = 2 * lp->cap;
        const double **col = realloc(lp->col, sizeof(double *) * cap);
        if (!col) return -1;
        lp->col = col;
        int *pos = realloc(lp->pos, sizeof(int) * (1 + lp->S + cap));
        if (!pos) return -1;
        lp->pos = pos;
        for (int j = 1 + lp->S + lp->cap; j < 1 + lp->S + cap; j++) pos[j] = -1;
        int *rj = realloc(lp->rj, sizeof(int) * (1 + lp->S + cap));
        if (!rj) return -1;
        lp->rj = rj;
        double *ra = realloc(lp->ra, sizeof(double) * (1 + lp->S + cap));
        if (!ra) return -1;
        lp->ra = ra;
        double *rd = realloc(lp->rd, sizeof(double) * (1 + lp->S + cap));
        if (!rd) return -1;
        lp->rd = rd;
        lp->cap = cap;
    }
    lp->col[lp->ncols++] = alpha;
    if (!lp->has_basis) lp->nactive = lp->ncols;
    return 0;
}

/* v . a_j (a_j the column of variable j) */
static double col_dot(const LP *lp, const double *v, int j) {
    int S = lp->S;
    if (j == 0) {
        double x = 0.0;
        for (int s = 0; s < S; s++) x += v[s];
        return x;
    }
    if (j <= S) return -v[j - 1];
    const double *a = lp->col[j - S - 1];
    double x = v[S];
    for (int s = 0; s < S; s++) x += a[s] * v[s];
    return x;
}

/* u = Binv a_j */
static void ftran(LP *lp, int j) {
    int m = lp->m, S = lp->S;
    (void)S;
    for (int i = 0; i < m; i++) lp->u[i] = col_dot(lp, lp->Binv + (size_t)i * m, j);
}

static void recompute_xB(LP *lp) {
    int m = lp->m;
    for (int i = 0; i < m; i++) {
        const double *r = lp->Binv + (size_t)i * m;
        double x = 0.0;
        for (int k = 0; k < m; k++) x += r[k] * lp->rhs[k];
        lp->xB[i] = x;
    }
}

/* Binv from the columns in head (Gauss-Jordan with partial pivoting); -1 when singular. */
static int refactor(LP *lp) {
    int m = lp->m, S = lp->S;
    double *B = lp->B, *X = lp->Binv;
    for (int p = 0; p < m; p++) { /* column p of B is a_{head[p]} */
        int j = lp->head[p];
        for (int i = 0; i < m; i++) B[(size_t)i * m + p] = 0.0;
        if (j == 0) {
            for (int s = 0; s < S; s++) B[(size_t)s * m + p] = 1.0;
        } else if (j <= S) {
            B[(size_t)(j - 1) * m + p] = -1.0;
        } else {
            const double *a = lp->col[j - S - 1];
            for (int s = 0; s < S; s++) B[(size_t)s * m + p] = a[s];
            B[(size_t)S * m + p] = 1.0;
        }
    }
    for (int i = 0; i < m; i++)
        for (int k = 0; k < m; k++) X[(size_t)i * m + k] = (i == k);
    for (int c = 0; c < m; c++) {
        int piv = c;
        double best = fabs(B[(size_t)c * m + c]);
        for (int i = c + 1; i < m; i++) {
            double v = fabs(B[(size_t)i * m + c]);
            if (v > best) { best = v; piv = i; }
        }
        if (best < 1e-12) return -1;
        if (piv != c) {
            for (int k = 0; k < m; k++) {
                double t = B[(size_t)c * m + k]; B[(size_t)c * m + k] = B[(size_t)piv * m + k]; B[(size_t)piv * m + k] = t;
                t = X[(size_t)c * m + k]; X[(size_t)c * m + k] = X[(size_t)piv * m + k]; X[(size_t)piv * m + k] = t;
            }
        }
        double inv = 1.0 / B[(size_t)c * m + c];
        for (int k = 0; k < m; k++) { B[(size_t)c * m + k] *= inv; X[(size_t)c * m + k] *= inv; }
        for (int i = 0; i < m; i++) {
            if (i == c) continue;
            double f = B[(size_t)i * m + c];
            if (f == 0.0) continue;
            for (int k = 0; k < m; k++) {
                B[(size_t)i * m + k] -= f * B[(size_t)c * m + k];
                X[(size_t)i * m + k] -= f * X[(size_t)c * m + k];
            }
        }
    }
    /* B reduced to I: X = B^-1 with rows in column order, i.e. row p of X belongs to head[p]. */
    lp->since_refactor = 0;
    recompute_xB(lp);
    return 0;
}

/* Variable q enters in row p (u = Binv a_q already computed). */
static int pivot(LP *lp, int p, int q) {
    int m = lp->m;
    double *Bp = lp->Binv + (size_t)p * m;
    double piv = lp->u[p];
    for (int k = 0; k < m; k++) Bp[k] /= piv;
    lp->xB[p] /= piv;
    for (int i = 0; i < m; i++) {
        if (i == p) continue;
        double f = lp->u[i];
        if (f == 0.0) continue;
        double *Bi = lp->Binv + (size_t)i * m;
        for (int k = 0; k < m; k++) Bi[k] -= f * Bp[k];
        lp->xB[i] -= f * lp->xB[p];
    }
    lp->pos[lp->head[p]] = -1;
    lp->head[p] = q;
    lp->pos[q] = p;
    lp->iterations++;
    if (++lp->since_refactor >= REFACTOR_EVERY) return refactor(lp);
    return 0;
}

/* Reduced cost of nonbasic variable j (y: t's row of Binv). */
static double reduced_cost(const LP *lp, const double *y, int j) {
    if (j <= lp->S) return y[j - 1]; /* sigma (j >= 1; t is always basic) */
    return -col_dot(lp, y, j);
}

static int iteration_cap(const LP *lp) { return 50 * (lp->m + lp->nactive) + 200; }

/* Primal simplex from a primal feasible basis, over the active columns. 0: optimal, -1: trouble. */
static int primal_simplex(LP *lp) {
    int S = lp->S, m = lp->m, nvar = 1 + S + lp->nactive;
    int degenerate = 0, cap = iteration_cap(lp), bland = 0;
    for (int it = 0;; it++) {
        if (it == cap) {
            if (bland) return -1;
            bland = 1; /* a long run: finish with Bland's rule, which cannot cycle */
            it = 0;
        }
        const double *y = lp->Binv + (size_t)lp->pos[0] * m;
        int q = -1;
        double dq = -DUAL_TOL;
        for (int j = 1; j < nvar; j++) {
            if (lp->pos[j] >= 0) continue;
            double d = reduced_cost(lp, y, j);
            if (d < dq) {
                q = j;
                if (bland || degenerate >= DEGENERATE_RUN) break; /* Bland: the first eligible */
                dq = d;
            }
        }
        if (q < 0) return 0;
        ftran(lp, q);
        /* Harris's ratio test: the largest pivot among rows within the relaxed bound. */
        double theta_max = INFINITY;
        for (int p = 0; p < m; p++) {
            if (p == lp->pos[0] || lp->u[p] <= PIVOT_TOL) continue;
            double r = (lp->xB[p] + PRIMAL_TOL) / lp->u[p];
            if (r < theta_max) theta_max = r;
        }
        if (theta_max == INFINITY) return -1; /* unbounded: cannot happen for this LP */
        int leave = -1;
        double best = 0.0;
        for (int p = 0; p < m; p++) {
            if (p == lp->pos[0] || lp->u[p] <= PIVOT_TOL) continue;
            double r = lp->xB[p] / lp->u[p];
            if (r > theta_max) continue;
            int better;
            if (bland || degenerate >= DEGENERATE_RUN)
                better = leave < 0 || lp->head[p] < lp->head[leave];
            else
                better = lp->u[p] > best;
            if (better) { leave = p; best = lp->u[p]; }
        }
        double step = lp->xB[leave] / lp->u[leave];
        degenerate = step <= PRIMAL_TOL ? degenerate + 1 : 0;
        if (pivot(lp, leave, q) < 0) return -1;
    }
}

/* Dual simplex from a dual feasible basis, over the active columns. 0: optimal, -1: trouble. */
static int dual_simplex(LP *lp) {
    int S = lp->S, m = lp->m, nvar = 1 + S + lp->nactive;
    int degenerate = 0, cap = iteration_cap(lp), bland = 0;
    for (int it = 0;; it++) {
        if (it == cap) {
            if (bland) return -1;
            bland = 1;
            it = 0;
        }
        int pt = lp->pos[0], leave = -1;
        int use_bland = bland || degenerate >= DEGENERATE_RUN;
        double worst = -PRIMAL_TOL;
        for (int p = 0; p < m; p++) {
            if (p == pt) continue; /* t is free */
            if (lp->xB[p] < worst) {
                if (use_bland) {
                    if (leave < 0 || lp->head[p] < lp->head[leave]) leave = p;
                } else {
                    leave = p;
                    worst = lp->xB[p];
                }
            }
        }
        if (leave < 0) return 0;
        const double *y = lp->Binv + (size_t)pt * m;
        const double *rho = lp->Binv + (size_t)leave * m;
        /* Harris: pass 1 bounds the step with relaxed reduced costs, pass 2 takes the largest |alpha|. */
        double theta_max = INFINITY;
        int nc = 0;
        for (int j = 1; j < nvar; j++) {
            if (lp->pos[j] >= 0) continue;
            double a = col_dot(lp, rho, j);
            if (a >= -PIVOT_TOL) continue;
            double d = reduced_cost(lp, y, j);
            double r = (d + DUAL_TOL) / -a;
            if (r < theta_max) theta_max = r;
            lp->rj[nc] = j; lp->ra[nc] = a; lp->rd[nc] = d; nc++;
        }
        if (theta_max == INFINITY) return -1; /* primal infeasible: cannot happen for this LP */
        int q = -1;
        double best = 0.0, dq = 0.0;
        for (int k = 0; k < nc; k++) {
            double a = lp->ra[k], d = lp->rd[k];
            if (d / -a > theta_max) continue;
            if (use_bland ? q < 0 : -a > best) { q = lp->rj[k]; best = -a; dq = d; }
        }
        degenerate = dq <= DUAL_TOL ? degenerate + 1 : 0;
        ftran(lp, q);
        if (fabs(lp->u[leave]) <= PIVOT_TOL) return -1;
        if (pivot(lp, leave, q) < 0) return -1;
    }
}

/* A fresh basis for the current rhs: lambda_0 = 1, t = max_s (c(s) - alpha_0(s)) and the
 * surplus of every other state basic; primal feasible by construction. All columns active. */
static int cold_start(LP *lp) {
    int S = lp->S;
    const double *a = lp->col[0];
    int star = 0;
    for (int s = 1; s < S; s++)
        if (lp->rhs[s] - a[s] > lp->rhs[star] - a[star]) star = s;
    for (int j = 0; j < 1 + S + lp->ncols; j++) lp->pos[j] = -1;
    int p = 0;
    lp->head[p++] = 1 + S; /* lambda_0 */
    lp->head[p++] = 0;     /* t */
    for (int s = 0; s < S; s++)
        if (s != star) lp->head[p++] = 1 + s;
    for (p = 0; p < lp->m; p++) lp->pos[lp->head[p]] = p;
    lp->nactive = lp->ncols;
    lp->has_basis = 0;
    if (refactor(lp) < 0) return -1;
    lp->has_basis = 1;
    return 0;
}

/* Largest infeasibility of the basic values (t excluded), from a fresh xB = Binv rhs. */
static double primal_infeasibility(LP *lp) {
    recompute_xB(lp);
    double worst = 0.0;
    for (int p = 0; p < lp->m; p++)
        if (p != lp->pos[0] && -lp->xB[p] > worst) worst = -lp->xB[p];
    return worst;
}

/* delta* for objective c (S values), the witness b (S values, unclipped). 0, or -1: no answer.
 * Each phase trusts the values it updates pivot by pivot; the end result is checked against a
 * fresh xB = Binv rhs (and, if need be, a refactored Binv), and re-optimised when it fails. */
static int lp_solve(LP *lp, const double *c, double *delta, double *b) {
    int S = lp->S, m = lp->m;
    if (lp->ncols == 0) return -1;
    double scale = 1.0;
    for (int s = 0; s < S; s++) {
        lp->rhs[s] = c[s];
        if (fabs(c[s]) > scale) scale = fabs(c[s]);
    }
    lp->rhs[S] = 1.0;
    int ok = -1;
    for (int start = lp->has_basis ? 0 : 1; start < 2 && ok < 0; start++) {
        if (start == 1) { /* no basis yet, or trouble: from a fresh basis (primal feasible) */
            if (cold_start(lp) < 0) break;
            if (primal_simplex(lp) < 0) continue;
        } else {
            recompute_xB(lp);
        }
        double worst = INFINITY;
        for (int round = 0; round < 3; round++) {
            ok = dual_simplex(lp);
            if (ok == 0) {
                lp->nactive = lp->ncols;
                ok = primal_simplex(lp);
            }
            if (ok < 0) break;
            worst = primal_infeasibility(lp);
            if (worst <= PRIMAL_TOL) break;
            /* drifted: a fresh inverse, then the dual simplex again (the basis is dual feasible) */
            if (refactor(lp) < 0) { ok = -1; break; }
        }
        /* What is left of an ill-conditioned basis is accepted when small: every drop is certified
         * (lp_certificate) and every witness checked in plain arithmetic by the caller. */
        if (ok == 0 && worst > 1e-7 * scale) ok = -1;
    }
    if (ok < 0) {
        lp->has_basis = 0;
        return -1;
    }
    recompute_xB(lp);
    const double *y = lp->Binv + (size_t)lp->pos[0] * m;
    *delta = lp->xB[lp->pos[0]];
    for (int s = 0; s < S; s++) b[s] = y[s];
    return 0;
}

/* An upper bound on delta* from the basis's own lambda (clipped to >= 0, normalised), in plain
 * arithmetic: max_s c(s) - sum_k lambda_k alpha_k(s). When it is below tol, dropping c is certain. */
static double lp_certificate(const LP *lp, const double *c) {
    int S = lp->S;
    double sum = 0.0;
    for (int p = 0; p < lp->m; p++)
        if (lp->head[p] > S && lp->xB[p] > 0.0) sum += lp->xB[p];
    if (!(sum > 0.0)) return INFINITY;
    double worst = -INFINITY;
    for (int s = 0; s < S; s++) {
        double v = c[s];
        for (int p = 0; p < lp->m; p++) {
            int j = lp->head[p];
            if (j > S && lp->xB[p] > 0.0) v -= lp->xB[p] / sum * lp->col[j - S - 1][s];
        }
        if (v > worst) worst = v;
    }
    return worst;
}

/* ------------------------------------------------------------------ one prune */
static double now_monotonic(void) { /* = time.perf_counter() on Linux (CLOCK_MONOTONIC) */
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* Row a lexicographically greater than row b (state 0 first). */
static int lex_greater(const double *a, const double *b, int S) {
    for (int s = 0; s < S; s++)
        if (a[s] != b[s]) return a[s] > b[s];
    return 0;
}

/* Rows i before j in lexicographic order, equal rows by index (a stable order). */
static int lex_before(const double *A, int S, int i, int j) {
    const double *a = A + (size_t)i * S, *b = A + (size_t)j * S;
    for (int s = 0; s < S; s++)
        if (a[s] != b[s]) return a[s] < b[s];
    return i < j;
}

/* Merge sort of idx[0..n) by lex_before (tmp: n ints); no global state, so safe without the GIL. */
static void lex_sort(const double *A, int S, int *idx, int *tmp, int n) {
    for (int width = 1; width < n; width *= 2) {
        for (int lo = 0; lo < n; lo += 2 * width) {
            int mid = lo + width < n ? lo + width : n, hi = lo + 2 * width < n ? lo + 2 * width : n;
            int i = lo, j = mid, o = lo;
            while (i < mid && j < hi) tmp[o++] = lex_before(A, S, idx[j], idx[i]) ? idx[j++] : idx[i++];
            while (i < mid) tmp[o++] = idx[i++];
            while (j < hi) tmp[o++] = idx[j++];
        }
        memcpy(idx, tmp, sizeof(int) * n);
    }
}

/* a >= b in every state */
static int geq_all(const double *a, const double *b, int S) {
    for (int s = 0; s < S; s++)
        if (a[s] < b[s]) return 0;
    return 1;
}

/* c(s) < k(s) + tol in every state: then c.b < k.b + tol everywhere, so delta* < tol. */
static int within_tol(const double *c, const double *k, int S, double tol) {
    for (int s = 0; s < S; s++)
        if (!(c[s] < k[s] + tol)) return 0;
    return 1;
}

static double dot(const double *a, const double *b, int S) {
    double x = 0.0;
    for (int s = 0; s < S; s++) x += a[s] * b[s];
    return x;
}

typedef struct {
    const double *A;
    int K, S;
    double tol;
    const double *P;  /* given points [nP][S] */
    int nP;
    long random_budget;
    PyObject *random_beliefs; /* callable (seed, S, n) -> [n, S] float64 beliefs */
    double deadline;  /* <= 0: none */
    int64_t *kept_out;
    double *wit_out;
    long lps, lp_witnesses, lp_resolves, lp_failures;
    double work; /* arithmetic done since the clock was last read (over_time) */
} PruneJob;

/* Read the clock about every CLOCK_EVERY multiply-adds: one prune of a large set can spend
 * seconds before its first LP (dominance, seed points, the first filter), and the deadline
 * must hold there too, while thousands of small prunes must not pay a clock read per row. */
#define CLOCK_EVERY 2e6

/* Account for `work` multiply-adds; 1 when the deadline (<= 0: none) has passed. */
static int over_time(PruneJob *J, double work) {
    if (J->deadline <= 0) return 0;
    J->work += work;
    if (J->work < CLOCK_EVERY) return 0;
    J->work = 0.0;
    return now_monotonic() > J->deadline;
}

#define NOMEM (-2)
#define TIMEOUT (-1)
#define CALLBACK_FAILED (-3)

typedef struct {
    int *cand, *kord, *queue, *wit_point;
    int *corner_best; /* [S]: the best row at each corner (large sets' dominance filter) */
    char *is_kept, *alive;
    double *wit, *R, *b, *vals;
    LP lp;
    int lp_ready;
} Work;

static void work_free(Work *w) {
    free(w->cand); free(w->kord); free(w->corner_best); free(w->queue); free(w->wit_point); free(w->is_kept); free(w->alive);
    free(w->wit); free(w->R); free(w->b); free(w->vals);
    if (w->lp_ready) lp_free(&w->lp);
}

static void keep(Work *w, int *nk, int i, const double *b, int S) {
    w->is_kept[i] = 1;
    memcpy(w->wit + (size_t)(*nk) * S, b, sizeof(double) * S);
    w->kord[(*nk)++] = i;
}

/* Best of the alive vectors (over cand) at b: values within tol of the best tie and the
 * lexicographically largest wins (pomdp-solve's tie-break). Returns the index; *vbest the best value. */
static int best_alive(const PruneJob *J, const Work *w, int C, const double *b, double *vbest) {
    const double *A = J->A;
    int S = J->S;
    double m = -INFINITY;
    for (int r = 0; r < C; r++) {
        int i = w->cand[r];
        if (!w->alive[i]) continue;
        double v = dot(A + (size_t)i * S, b, S);
        w->vals[r] = v;
        if (v > m) m = v;
    }
    int best = -1;
    for (int r = 0; r < C; r++) {
        int i = w->cand[r];
        if (!w->alive[i] || w->vals[r] < m - J->tol) continue;
        if (best < 0 || lex_greater(A + (size_t)i * S, A + (size_t)best * S, S)) best = i;
    }
    *vbest = m;
    return best;
}

static int prune_run(PruneJob *J) {
    const double *A = J->A;
    int K = J->K, S = J->S;
    double tol = J->tol;
    if (K == 0) return 0;
    if (K == 1) {
        J->kept_out[0] = 0;
        for (int s = 0; s < S; s++) J->wit_out[s] = s == 0;
        return 1;
    }
    Work w;
    memset(&w, 0, sizeof(w));
    int rc = NOMEM;
    w.cand = malloc(sizeof(int) * K);
    w.kord = malloc(sizeof(int) * K);
    w.corner_best = malloc(sizeof(int) * (size_t)S);
    w.queue = malloc(sizeof(int) * 2 * (size_t)K);
    w.wit_point = malloc(sizeof(int) * K);
    w.is_kept = calloc(K, 1);
    w.alive = calloc(K, 1);
    w.wit = malloc(sizeof(double) * (size_t)K * S);
    w.b = malloc(sizeof(double) * S);
    w.vals = malloc(sizeof(double) * K);
    if (!w.cand || !w.kord || !w.corner_best || !w.queue || !w.wit_point || !w.is_kept || !w.alive || !w.wit || !w.b || !w.vals)
        goto done;

    /* 1. duplicates (the first copy stays) and 2. weak pointwise dominance. In lexicographic
     * order equal rows are adjacent (by index), and a row's dominators come after it. */
    int *order = w.queue; /* scratch for now */
    for (int i = 0; i < K; i++) order[i] = i;
    lex_sort(A, S, order, w.kord, K);
    int N = 0; /* distinct rows, in lexicographic order, into order[0..N) */
    for (int r = 0; r < K; r++) {
        if (N > 0 && geq_all(A + (size_t)order[r] * S, A + (size_t)order[N - 1] * S, S)
            && geq_all(A + (size_t)order[N - 1] * S, A + (size_t)order[r] * S, S))
            continue;
        order[N++] = order[r];
    }
    char *dominated = w.alive; /* scratch: zeroed again below */
    if ((double)N * N * S <= 1e7) {
        for (int r = 0; r < N; r++) {
            const double *a = A + (size_t)order[r] * S;
            for (int q = r + 1; q < N; q++)
                if (geq_all(A + (size_t)order[q] * S, a, S)) { dominated[order[r]] = 1; break; }
        }
    } else { /* large sets: only the best rows at the corners dominate (the LPs do the rest) */
        /* (S entries: not kord's K, which is shorter whenever the states outnumber the rows) */
        int *by = w.corner_best;
        for (int s = 0; s < S; s++) {
            int bi = order[0];
            for (int r = 1; r < N; r++)
                if (A[(size_t)order[r] * S + s] > A[(size_t)bi * S + s]) bi = order[r];
            by[s] = bi;
        }
        for (int r = 0; r < N; r++) {
            int i = order[r];
            for (int s = 0; s < S; s++)
                if (by[s] != i && geq_all(A + (size_t)by[s] * S, A + (size_t)i * S, S)) { dominated[i] = 1; break; }
            if (over_time(J, (double)S * S)) { rc = TIMEOUT; goto done; }
        }
    }
    if (J->deadline > 0 && now_monotonic() > J->deadline) { rc = TIMEOUT; goto done; } /* after the sort */
    char *in_cand = w.is_kept; /* scratch: zeroed again below */
    for (int r = 0; r < N; r++)
        if (!dominated[order[r]]) in_cand[order[r]] = 1;
    int C = 0;
    for (int i = 0; i < K; i++)
        if (in_cand[i]) w.cand[C++] = i;
    memset(w.is_kept, 0, K);
    memset(w.alive, 0, K);

    /* 3. witnesses without LPs: the simplex's corners (ties: lexicographically largest). */
    int nk = 0;
    double *corner = w.b;
    for (int s = 0; s < S; s++) {
        double m = -INFINITY;
        for (int r = 0; r < C; r++) {
            double v = A[(size_t)w.cand[r] * S + s];
            if (v > m) m = v;
        }
        int best = -1;
        for (int r = 0; r < C; r++) {
            int i = w.cand[r];
            if (A[(size_t)i * S + s] < m - tol) continue;
            if (best < 0 || lex_greater(A + (size_t)i * S, A + (size_t)best * S, S)) best = i;
        }
        if (!w.is_kept[best]) {
            for (int t = 0; t < S; t++) corner[t] = t == s;
            keep(&w, &nk, best, corner, S);
        }
    }
    /* ... then the given points and a few random ones (seeded by C, S): the best vector at a
     * point where it wins by more than tol is kept, with that point as its witness. */
    long n_random = 4L * S > 64 ? 4L * S : 64;
    long by_budget = J->random_budget / (C > 0 ? C : 1);
    if (by_budget < n_random) n_random = by_budget;
    if (!(n_random > 0 && C > (S > nk + J->nP ? S : nk + J->nP))) n_random = 0;
    if (nk < C && J->nP + n_random > 0) {
        if (n_random > 0) { /* random_beliefs(seed=C, S, n) from Python (numpy's generator, cached there) */
            w.R = malloc(sizeof(double) * (size_t)n_random * S);
            if (!w.R) goto done;
            PyGILState_STATE gil = PyGILState_Ensure();
            PyObject *arr = PyObject_CallFunction(J->random_beliefs, "iil", C, S, n_random);
            Py_buffer rb;
            int got = 0;
            if (arr && PyObject_GetBuffer(arr, &rb, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) == 0) {
                got = rb.len == (Py_ssize_t)(sizeof(double) * n_random * S) && rb.format && strcmp(rb.format, "d") == 0;
                if (got) memcpy(w.R, rb.buf, rb.len);
                PyBuffer_Release(&rb);
            }
            Py_XDECREF(arr);
            if (!got) {
                if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "random_beliefs returned a wrong array");
                PyGILState_Release(gil);
                rc = CALLBACK_FAILED;
                goto done;
            }
            PyGILState_Release(gil);
        }
        for (int i = 0; i < K; i++) w.wit_point[i] = -1;
        long total = J->nP + n_random;
        for (long p = 0; p < total; p++) {
            const double *x = p < J->nP ? J->P + (size_t)p * S : w.R + (size_t)(p - J->nP) * S;
            double top = -INFINITY, second = -INFINITY;
            int arg = -1;
            for (int r = 0; r < C; r++) {
                double v = dot(A + (size_t)w.cand[r] * S, x, S);
                if (v > top) { second = top; top = v; arg = w.cand[r]; }
                else if (v > second) second = v;
            }
            if ((C < 2 || top - second > tol) && w.wit_point[arg] < 0) w.wit_point[arg] = (int)p;
            if (over_time(J, (double)C * S)) { rc = TIMEOUT; goto done; }
        }
        for (int r = 0; r < C; r++) {
            int i = w.cand[r];
            long p = w.wit_point[i];
            if (p < 0 || w.is_kept[i]) continue;
            keep(&w, &nk, i, p < J->nP ? J->P + (size_t)p * S : w.R + (size_t)(p - J->nP) * S, S);
        }
    }

    /* 4. Lark's filter over the rest: one LP per candidate against the kept vectors. */
    int nq = 0;
    for (int r = 0; r < C; r++) {
        int i = w.cand[r];
        if (w.is_kept[i]) continue;
        const double *c = A + (size_t)i * S;
        int drop = 0;
        for (int k = 0; k < nk && !drop; k++) drop = within_tol(c, A + (size_t)w.kord[k] * S, S, tol);
        if (!drop) { w.queue[nq++] = i; w.alive[i] = 1; }
        if (over_time(J, (double)nk * S)) { rc = TIMEOUT; goto done; }
    }
    if (nq > 0) {
        if (lp_init(&w.lp, S, nk + nq) < 0) goto done;
        w.lp_ready = 1;
        for (int k = 0; k < nk; k++)
            if (lp_add(&w.lp, A + (size_t)w.kord[k] * S) < 0) goto done;
        int filtered_upto = nk; /* kept vectors every alive candidate was checked against */
        int *checked = w.wit_point; /* checked[i]: kept vectors candidate i was checked against */
        for (int q = 0; q < nq; q++) checked[w.queue[q]] = nk;
        double *b = w.b;
        for (int qi = 0; qi < nq; qi++) {
            int c = w.queue[qi];
            if (!w.alive[c]) continue;
            if (J->deadline > 0 && now_monotonic() > J->deadline) { rc = TIMEOUT; goto done; } /* each LP */
            /* Re-filter every alive vector against the vectors kept since the last pass, in batches
             * (as before: those within tol everywhere of a kept vector are out). */
            if (nk - filtered_upto >= (nk / 8 > 1 ? nk / 8 : 1)) {
                for (int r = 0; r < C; r++) {
                    int i = w.cand[r];
                    if (!w.alive[i]) continue;
                    for (int k = (checked[i] > filtered_upto ? checked[i] : filtered_upto); k < nk; k++)
                        if (within_tol(A + (size_t)i * S, A + (size_t)w.kord[k] * S, S, tol)) { w.alive[i] = 0; break; }
                    checked[i] = nk;
                    if (over_time(J, (double)(nk - filtered_upto) * S)) { rc = TIMEOUT; goto done; }
                }
                filtered_upto = nk;
                if (!w.alive[c]) continue;
            }
            const double *cv = A + (size_t)c * S;
            /* (this candidate alone against the few kept since: no LP when within tol of one) */
            int drop = 0;
            for (int k = checked[c]; k < nk && !drop; k++) drop = within_tol(cv, A + (size_t)w.kord[k] * S, S, tol);
            checked[c] = nk;
            if (drop) { w.alive[c] = 0; continue; }
            double delta;
            J->lps++;
            int vbest_ok = 0, j = -1;
            for (int attempt = 0; attempt < 2 && !vbest_ok; attempt++) {
                if (attempt == 1) { /* the warm basis gave an answer that does not hold: from scratch */
                    J->lp_resolves++;
                    w.lp.has_basis = 0;
                }
                if (lp_solve(&w.lp, cv, &delta, b) < 0) {
                    J->lp_failures++;
                    break;
                }
                if (delta < tol) {
                    double ub = lp_certificate(&w.lp, cv);
                    if (ub < tol) break;  /* certain: c never wins by tol */
                    if (attempt == 0) continue;
                    delta = ub;           /* unresolved: let the witness check below decide */
                }
                double sum = 0.0;
                for (int s = 0; s < S; s++) { if (b[s] < 0.0) b[s] = 0.0; sum += b[s]; }
                if (!(sum > 0.0)) continue;
                for (int s = 0; s < S; s++) b[s] /= sum;
                double vbest;
                j = best_alive(J, &w, C, b, &vbest);
                double vkept = -INFINITY;
                for (int k = 0; k < nk; k++) {
                    double v = dot(A + (size_t)w.kord[k] * S, b, S);
                    if (v > vkept) vkept = v;
                }
                /* The LP's witness must hold up in plain arithmetic; otherwise no witness. */
                vbest_ok = vbest - vkept > 0.0;
            }
            if (!vbest_ok) { w.alive[c] = 0; continue; }
            J->lp_witnesses++;
            w.alive[j] = 0;
            keep(&w, &nk, j, b, S);
            if (lp_add(&w.lp, A + (size_t)j * S) < 0) goto done;
            if (j != c) w.queue[nq++] = c; /* c still waits for its own verdict */
        }
    }

    /* Out: kept indices ascending, each with its witness. */
    {
        int *slot = w.wit_point;
        for (int r = 0; r < nk; r++) slot[w.kord[r]] = r;
        int n = 0;
        for (int i = 0; i < K; i++) {
            if (!w.is_kept[i]) continue;
            J->kept_out[n] = i;
            memcpy(J->wit_out + (size_t)n * S, w.wit + (size_t)slot[i] * S, sizeof(double) * S);
            n++;
        }
        rc = n;
    }
done:
    work_free(&w);
    return rc;
}

/* ------------------------------------------------------------------ Python bindings */
/* A C-contiguous buffer of doubles with ndim dimensions ("what" names it in errors). */
static int get_doubles(PyObject *obj, Py_buffer *view, int ndim, int writable, const char *what) {
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, view, flags) < 0) {
        PyErr_Clear();
        PyErr_Format(PyExc_ValueError, "%s must be a C-contiguous %sfloat64 array", what, writable ? "writable " : "");
        return -1;
    }
    if (view->itemsize != 8 || !view->format || strcmp(view->format, "d") != 0) {
        PyErr_Format(PyExc_ValueError, "%s must hold float64 values, got format '%s'", what,
                     view->format ? view->format : "?");
        PyBuffer_Release(view);
        return -1;
    }
    if (view->ndim != ndim) {
        PyErr_Format(PyExc_ValueError, "%s must be a %d-D array, got %d-D", what, ndim, view->ndim);
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

static int all_finite(const double *x, Py_ssize_t n) {
    for (Py_ssize_t i = 0; i < n; i++)
        if (!isfinite(x[i])) return 0;
    return 1;
}

static PyObject *py_prune(PyObject *Py_UNUSED(self), PyObject *args) {
    PyObject *alphas_obj, *points_obj, *kept_obj, *wit_obj, *random_beliefs;
    double tol, deadline;
    long long budget;
    if (!PyArg_ParseTuple(args, "OdOLOdOO:prune", &alphas_obj, &tol, &points_obj, &budget, &random_beliefs, &deadline,
                          &kept_obj, &wit_obj))
        return NULL;
    if (!(tol >= 0.0) || !isfinite(tol)) return PyErr_Format(PyExc_ValueError, "tol must be >= 0, got %R", PyTuple_GET_ITEM(args, 1));
    /* Every resource that `out:` releases is declared (and empty) before the first `goto out`. */
    Py_buffer a = {0}, p = {0}, k = {0}, w = {0};
    int have_k = 0, have_w = 0;
    Py_ssize_t nP = 0;
    double *Pall = NULL;
    PyObject *result = NULL;
    if (get_doubles(alphas_obj, &a, 2, 0, "alphas") < 0) return NULL;
    Py_ssize_t K = a.shape[0], S = a.shape[1];
    if (S < 1 || K > INT32_MAX / 2 || S > INT32_MAX / 2) {
        PyErr_Format(PyExc_ValueError, "alphas must be a [K, S] array with S >= 1, got shape (%zd, %zd)", K, S);
        goto out;
    }
    if (!all_finite(a.buf, K * S)) { PyErr_SetString(PyExc_ValueError, "alphas has a non-finite entry"); goto out; }
    /* points: None or a tuple of [P_i, S] arrays, used in that order (no vstack needed) */
    if (points_obj != Py_None) {
        if (!PyTuple_Check(points_obj)) { PyErr_SetString(PyExc_ValueError, "points must be None or a tuple of [P, S] arrays"); goto out; }
        Py_ssize_t nparts = PyTuple_GET_SIZE(points_obj);
        for (int pass = 0; pass < 2; pass++) { /* pass 0 checks and counts, pass 1 copies */
            Py_ssize_t row = 0;
            for (Py_ssize_t q = 0; q < nparts; q++) {
                if (get_doubles(PyTuple_GET_ITEM(points_obj, q), &p, 2, 0, "points") < 0) goto out;
                Py_ssize_t rows = p.shape[0], cols = p.shape[1];
                if (rows > 0 && cols != S) {
                    PyErr_Format(PyExc_ValueError, "points must be [P, %zd] beliefs (one per row), got shape (%zd, %zd)", S, rows, cols);
                    PyBuffer_Release(&p);
                    goto out;
                }
                if (pass == 0 && !all_finite(p.buf, rows * cols)) {
                    PyErr_SetString(PyExc_ValueError, "points has a non-finite entry");
                    PyBuffer_Release(&p);
                    goto out;
                }
                if (pass == 1 && rows > 0) memcpy(Pall + row * S, p.buf, sizeof(double) * rows * S);
                row += rows;
                PyBuffer_Release(&p);
            }
            if (pass == 0) {
                if (row > INT32_MAX / 2) { PyErr_SetString(PyExc_ValueError, "too many points"); goto out; }
                nP = row;
                if (nP == 0) break;
                Pall = malloc(sizeof(double) * nP * S);
                if (!Pall) { PyErr_NoMemory(); goto out; }
            }
        }
    }
    if (PyObject_GetBuffer(kept_obj, &k, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | PyBUF_WRITABLE) < 0) {
        PyErr_Clear(); /* (the exporter's own message does not say which argument) */
        PyErr_SetString(PyExc_ValueError, "kept_out must be a writable C-contiguous int64 array of at least K entries");
        goto out;
    }
    have_k = 1;
    if (k.itemsize != 8 || !k.format || !(strcmp(k.format, "q") == 0 || strcmp(k.format, "l") == 0) || k.len < 8 * K) {
        PyErr_SetString(PyExc_ValueError, "kept_out must be a writable C-contiguous int64 array of at least K entries");
        goto out;
    }
    if (get_doubles(wit_obj, &w, 2, 1, "witness_out") < 0) goto out;
    have_w = 1;
    if (w.len < (Py_ssize_t)sizeof(double) * K * S) {
        PyErr_SetString(PyExc_ValueError, "witness_out must hold at least K x S values");
        goto out;
    }
    PruneJob job = {a.buf, (int)K, (int)S, tol, Pall, (int)nP, (long)budget, random_beliefs, deadline,
                    k.buf, w.buf, 0, 0, 0, 0, 0.0};
    int n;
    Py_BEGIN_ALLOW_THREADS
    n = prune_run(&job);
    Py_END_ALLOW_THREADS
    if (n == NOMEM) { PyErr_NoMemory(); goto out; }
    if (n == CALLBACK_FAILED) goto out;
    result = Py_BuildValue("(illll)", n, job.lps, job.lp_witnesses, job.lp_resolves, job.lp_failures);
out:
    PyBuffer_Release(&a);
    free(Pall);
    if (have_k) PyBuffer_Release(&k);
    if (have_w) PyBuffer_Release(&w);
    return result;
}

/* WitnessLP: the LP of Lark's filter on its own (it copies the vectors it is given). */
typedef struct {
    PyObject_HEAD
    LP lp;
    double **copies;
    int ncopies, capcopies;
} WitnessLPObject;

static void wlp_dealloc(WitnessLPObject *o) {
    for (int i = 0; i < o->ncopies; i++) free(o->copies[i]);
    free(o->copies);
    if (o->lp.m) lp_free(&o->lp);
    Py_TYPE(o)->tp_free((PyObject *)o);
}

static int wlp_init(WitnessLPObject *o, PyObject *args, PyObject *kw) {
    int S;
    static char *names[] = {"num_states", NULL};
    if (!PyArg_ParseTupleAndKeywords(args, kw, "i:WitnessLP", names, &S)) return -1;
    if (S < 1) { PyErr_Format(PyExc_ValueError, "num_states must be >= 1, got %d", S); return -1; }
    if (o->lp.m) lp_free(&o->lp);
    if (lp_init(&o->lp, S, 8) < 0) { PyErr_NoMemory(); return -1; }
    return 0;
}

static int wlp_vector(WitnessLPObject *o, PyObject *obj, Py_buffer *v, const char *what) {
    if (!o->lp.m) { PyErr_SetString(PyExc_ValueError, "WitnessLP was not initialised"); return -1; }
    if (get_doubles(obj, v, 1, 0, what) < 0) return -1;
    if (v->shape[0] != o->lp.S || !all_finite(v->buf, v->shape[0])) {
        PyErr_Format(PyExc_ValueError, "%s must be %d finite values, got %zd values%s", what, o->lp.S, v->shape[0],
                     v->shape[0] == o->lp.S ? " with a non-finite one" : "");
        PyBuffer_Release(v);
        return -1;
    }
    return 0;
}

static PyObject *wlp_add(WitnessLPObject *o, PyObject *arg) {
    Py_buffer v;
    if (wlp_vector(o, arg, &v, "alpha") < 0) return NULL;
    double *copy = malloc(sizeof(double) * o->lp.S);
    if (!copy || (o->ncopies == o->capcopies && !(o->copies = realloc(o->copies, sizeof(double *) * (o->capcopies = 2 * o->capcopies + 8))))) {
        free(copy); PyBuffer_Release(&v); return PyErr_NoMemory();
    }
    memcpy(copy, v.buf, sizeof(double) * o->lp.S);
    PyBuffer_Release(&v);
    o->copies[o->ncopies++] = copy;
    if (lp_add(&o->lp, copy) < 0) return PyErr_NoMemory();
    Py_RETURN_NONE;
}

static PyObject *wlp_solve(WitnessLPObject *o, PyObject *arg) {
    Py_buffer v;
    if (wlp_vector(o, arg, &v, "c") < 0) return NULL;
    if (o->lp.ncols == 0) { PyBuffer_Release(&v); PyErr_SetString(PyExc_ValueError, "WitnessLP.solve needs at least one added vector"); return NULL; }
    int S = o->lp.S;
    double *b = malloc(sizeof(double) * S), delta = 0.0;
    if (!b) { PyBuffer_Release(&v); return PyErr_NoMemory(); }
    int rc = lp_solve(&o->lp, v.buf, &delta, b);
    PyBuffer_Release(&v);
    if (rc < 0) { free(b); return Py_BuildValue("(dO)", -INFINITY, Py_None); }
    PyObject *bt = PyTuple_New(S);
    if (!bt) { free(b); return NULL; }
    for (int s = 0; s < S; s++) PyTuple_SET_ITEM(bt, s, PyFloat_FromDouble(b[s]));
    free(b);
    PyObject *r = Py_BuildValue("(dN)", delta, bt);
    return r;
}

static PyObject *wlp_get_iterations(WitnessLPObject *o, void *Py_UNUSED(closure)) { return PyLong_FromLong(o->lp.iterations); }

static PyMethodDef wlp_methods[] = {
    {"add", (PyCFunction)wlp_add, METH_O, "add(alpha): a kept vector (a new column)."},
    {"solve", (PyCFunction)wlp_solve, METH_O,
     "solve(c) -> (delta, b): delta* = max_b c.b - max_k alpha_k.b over the simplex and an optimal b "
     "(unclipped); (-inf, None) when the LP could not be solved."},
    {NULL, NULL, 0, NULL}};

static PyGetSetDef wlp_getset[] = {
    {"iterations", (getter)wlp_get_iterations, NULL, "simplex pivots so far", NULL}, {NULL}};

static PyTypeObject WitnessLPType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "pearl_pomdp.solvers._prune.WitnessLP",
    .tp_basicsize = sizeof(WitnessLPObject),
    .tp_dealloc = (destructor)wlp_dealloc,
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "WitnessLP(num_states): the LP of Lark's filter, warm-started across solve() and add() calls.",
    .tp_methods = wlp_methods,
    .tp_getset = wlp_getset,
    .tp_init = (initproc)wlp_init,
    .tp_new = PyType_GenericNew,
};

static PyMethodDef methods[] = {
    {"prune", py_prune, METH_VARARGS,
     "prune(alphas, tol, points, random_budget, random_beliefs, deadline, kept_out, witness_out) -> (n, lps, lp_witnesses, lp_resolves, lp_failures)\n"
     "One prune (see pearl_pomdp.solvers.prune.prune). Writes the n kept indices (ascending) into kept_out\n"
     "and their witnesses into the first n rows of witness_out; n = -1 when deadline (a time.perf_counter()\n"
     "value, <= 0 for none) passed."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_prune", "The exact solver's pruning kernel (see prune.py).", -1, methods,
                                    NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__prune(void) {
    if (PyType_Ready(&WitnessLPType) < 0) return NULL;
    PyObject *m = PyModule_Create(&module);
    if (!m) return NULL;
    Py_INCREF(&WitnessLPType);
    if (PyModule_AddObject(m, "WitnessLP", (PyObject *)&WitnessLPType) < 0) {
        Py_DECREF(&WitnessLPType);
        Py_DECREF(m);
        return NULL;
    }
    return m;
}

/* The per-belief inner loops of the point-based solver (pearl_pomdp/solvers/point_based.py).
 *
 * Why C: on small models a backup is a few dozen tiny numpy calls, and their fixed cost
 * (~3-5 us each) is what the time goes to (tiger.95: ~300 us per backup, SARSOP ~10 us).
 * These loops are the only implementation of what they compute (no Python twin to keep in
 * sync); they are used for every model size.
 *
 * No numpy C API: every array is passed through the buffer protocol ("y*" read-only,
 * "w*" writable), C-contiguous, with the dtypes the docstrings name (float64 = double,
 * int64 = long long). The Python caller allocates the outputs and owns every buffer.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

typedef long long i64;

#define REL(b) PyBuffer_Release(&(b))

static int cmp_i64(const void *x, const void *y) {
    i64 a = *(const i64 *)x, b = *(const i64 *)y;
    return (a > b) - (a < b);
}

static int check_len(Py_buffer *b, Py_ssize_t itemsize, Py_ssize_t need, const char *name) {
    if (b->len < need * itemsize) {
        PyErr_Format(PyExc_ValueError, "_pointbased_kernel: buffer %s holds %zd bytes, needs %zd",
                     name, b->len, need * itemsize);
        return 0;
    }
    return 1;
}

/* successors(idx, val, t_ptr, t_ind, t_dat, O, A, S, Z, bT, pos, U_out, C_out, p_out, live_out)
 *   -> (nU, nlive)
 *
 * For the belief val (float64 [n]) on states idx (int64 [n]) and T as one CSR S x (A*S) block
 * (t_ptr int64 [S+1], t_ind int64, t_dat float64), O float64 [A, S, Z]:
 *   bT[a*S+s'] = sum_i val[i] T[a][idx[i], s']   (bT: float64 [A*S] scratch, all zero on entry
 *                                                  and on exit)
 *   U_out[:nU]  = the states s' with bT[a*S+s'] > 0 for some a, ascending
 *   C_out       = [A*Z, nU] (row-major, contiguous at the start of the buffer):
 *                 C[a*Z+o, j] = bT[a*S+U[j]] O[a, U[j], o] / p[a*Z+o]  (unnormalised zeros
 *                 where p <= 1e-300)
 *   p_out[a*Z+o] = P(o | b, a);  live_out[:nlive] = the flat indices a*Z+o with p > 1e-300.
 * nlive = -1 (and only U_out filled) when C_out is shorter than A*Z*nU doubles.
 * pos: int64 [S] scratch, all -1 on entry and on exit.
 * allowed (optional, uint8 [A]; empty or absent: every action): the actions whose successors
 * are wanted; the others get p = 0, zero rows of C and no live entries, and their mass does
 * not put a state into U (the policy-contingent parents of the hierarchy planner). */
static PyObject *successors(PyObject *Py_UNUSED(self), PyObject *args) {
    Py_buffer idx, val, tptr, tind, tdat, O, bT, pos, Uo, Co, po, lo;
    Py_buffer alb = {0};
    Py_ssize_t A, S, Z;
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*y*nnnw*w*w*w*w*w*|y*", &idx, &val, &tptr, &tind, &tdat, &O, &A, &S,
                          &Z, &bT, &pos, &Uo, &Co, &po, &lo, &alb))
        return NULL;
    PyObject *ret = NULL;
    const unsigned char *al = (alb.buf != NULL && alb.len > 0) ? (const unsigned char *)alb.buf : NULL;
    Py_ssize_t n = idx.len / (Py_ssize_t)sizeof(i64);
    if (al != NULL && alb.len < A) {
        PyErr_Format(PyExc_ValueError, "_pointbased_kernel: buffer allowed holds %zd bytes, needs %zd", alb.len, A);
        goto done;
    }
    if (!check_len(&val, 8, n, "val") || !check_len(&tptr, 8, S + 1, "t_ptr") || !check_len(&O, 8, A * S * Z, "O")
        || !check_len(&bT, 8, A * S, "bT") || !check_len(&pos, 8, S, "pos") || !check_len(&Uo, 8, S, "U_out")
        || !check_len(&po, 8, A * Z, "p_out") || !check_len(&lo, 8, A * Z, "live_out"))
        goto done;
    {
        const i64 *ix = (const i64 *)idx.buf, *tp = (const i64 *)tptr.buf, *ti = (const i64 *)tind.buf;
        const double *v = (const double *)val.buf, *td = (const double *)tdat.buf, *Ob = (const double *)O.buf;
        double *bt = (double *)bT.buf, *C = (double *)Co.buf, *p = (double *)po.buf;
        i64 *ps = (i64 *)pos.buf, *U = (i64 *)Uo.buf, *live = (i64 *)lo.buf;
        Py_ssize_t ntind = tind.len / 8;
        /* Accumulate b*T[a] for every a; mark the reached states (pos = 1 as a flag first). */
        for (Py_ssize_t i = 0; i < n; i++) {
            i64 s = ix[i];
            if (s < 0 || s >= S) { PyErr_SetString(PyExc_IndexError, "_pointbased_kernel.successors: state out of range"); goto clean_bt; }
            double w = v[i];
            for (i64 e = tp[s]; e < tp[s + 1]; e++) {
                if (e < 0 || e >= ntind) { PyErr_SetString(PyExc_IndexError, "_pointbased_kernel.successors: bad t_ptr"); goto clean_bt; }
                i64 c = ti[e];
                if (al != NULL && !al[c / S]) continue;
                bt[c] += w * td[e];
                ps[c % S] = 0;
            }
        }
        Py_ssize_t nU = 0;
        /* U: the touched states with positive mass under some action, then sorted ascending. */
        for (Py_ssize_t i = 0; i < n; i++) {
            i64 s = ix[i];
            for (i64 e = tp[s]; e < tp[s + 1]; e++) {
                i64 c = ti[e] % S;
                if (ps[c] == 0) {
                    /* reached with positive mass under some action? */
                    int positive = 0;
                    for (Py_ssize_t a = 0; a < A; a++)
                        if (bt[a * S + c] > 0.0) { positive = 1; break; }
                    ps[c] = positive ? -2 : -3;  /* -2: in U (not yet numbered), -3: touched, not in U */
                    if (positive) U[nU++] = c;
                }
            }
        }
        /* sort U ascending (insertion sort for short lists, qsort otherwise) */
        if (nU < 64) {
            for (Py_ssize_t i = 1; i < nU; i++) {
                i64 x = U[i];
                Py_ssize_t j = i - 1;
                while (j >= 0 && U[j] > x) { U[j + 1] = U[j]; j--; }
                U[j + 1] = x;
            }
        } else {
            qsort(U, (size_t)nU, sizeof(i64), cmp_i64);
        }
        if (Co.len < A * Z * nU * 8) {  /* the caller grows C_out and calls again */
            ret = Py_BuildValue("nn", nU, (Py_ssize_t)-1);
            goto clean_bt;
        }
        Py_ssize_t nlive = 0;
        for (Py_ssize_t a = 0; a < A; a++) {
            const double *Oa = Ob + a * S * Z;
            double *rows = C + a * Z * nU;
            for (Py_ssize_t o = 0; o < Z; o++) p[a * Z + o] = 0.0;
            if (al != NULL && !al[a]) {
                memset(rows, 0, sizeof(double) * (size_t)(Z * nU));
                continue;
            }
            for (Py_ssize_t j = 0; j < nU; j++) {
                double w = bt[a * S + U[j]];
                const double *Os = Oa + U[j] * Z;
                for (Py_ssize_t o = 0; o < Z; o++) {
                    double x = w * Os[o];
                    rows[o * nU + j] = x;
                    p[a * Z + o] += x;
                }
            }
            for (Py_ssize_t o = 0; o < Z; o++) {
                double q = p[a * Z + o];
                if (q > 1e-300) {
                    live[nlive++] = a * Z + o;
                    double inv = 1.0 / q;
                    double *r = rows + o * nU;
                    for (Py_ssize_t j = 0; j < nU; j++) r[j] *= inv;
                }
            }
        }
        ret = Py_BuildValue("nn", nU, nlive);
    clean_bt:
        /* restore the scratch: bT zero, pos -1 */
        for (Py_ssize_t i = 0; i < n; i++) {
            i64 s = ix[i];
            if (s < 0 || s >= S) break;
            for (i64 e = tp[s]; e < tp[s + 1]; e++) {
                if (e < 0 || e >= ntind) break;
                i64 c = ti[e];
                bt[c] = 0.0;
                ps[c % S] = -1;
            }
        }
    }
done:
    REL(idx); REL(val); REL(tptr); REL(tind); REL(tdat); REL(O); REL(bT); REL(pos); REL(Uo); REL(Co); REL(po); REL(lo);
    if (alb.obj != NULL) REL(alb);
    return ret;
}


/* The rows of one lower_rows block at a time: each vector row G[U[j]] is read once for the
 * block (the solver's Gamma is a few hundred vectors over hundreds of states, ~1 MB: read once
 * per row it was the kernel's cost), and every v_k still adds its terms in ascending j, so the
 * numbers are those of one row at a time bit for bit. The AVX2 clone (where the CPU has it) only
 * widens the loop over k; setup.py builds with -ffp-contract=off, so no multiply-add is fused. */
#define LOWER_BLOCK 8

#if defined(__GNUC__) && defined(__x86_64__) && defined(__has_attribute)
#if __has_attribute(target_clones)
#define WIDE_CLONES __attribute__((target_clones("avx2", "default")))
#endif
#endif
#ifndef WIDE_CLONES
#define WIDE_CLONES
#endif

/* acc[b * nk + k] = sum_j c_b[j] GT[U[j], k0 + k] for the nb rows c_b = C + r_b * nU (zero c skipped).
 * Returns -1, or the index j of a state out of range (with a nonzero weight). */
WIDE_CLONES
static Py_ssize_t lower_block(const double *C, Py_ssize_t nU, const i64 *U, const i64 *r, Py_ssize_t nb,
                              const double *G, Py_ssize_t nG, Py_ssize_t cap, Py_ssize_t k0, Py_ssize_t nk,
                              double *acc) {
    for (Py_ssize_t x = 0; x < nb * nk; x++) acc[x] = 0.0;
    for (Py_ssize_t j = 0; j < nU; j++) {
        const double *g = G + U[j] * cap + k0;
        int checked = 0;
        for (Py_ssize_t b = 0; b < nb; b++) {
            double w = C[r[b] * nU + j];
            if (w == 0.0) continue;
            if (!checked) {
                if (U[j] < 0 || (U[j] + 1) * cap > nG) return j;
                checked = 1;
            }
            double *a = acc + b * nk;
            for (Py_ssize_t k = 0; k < nk; k++) a[k] += w * g[k];
        }
    }
    return -1;
}

/* lower_rows(C, nU, U, rows, GT, cap, k0, K, lb, best, only_better) -> None
 *
 * For each flat row r in rows (int64): v_k = sum_j C[r, j] GT[U[j], k] for k in [k0, K)
 * (C float64 [*, nU] row-major; GT float64 [S, cap] row-major; zero entries of C skipped),
 * j* = the first maximiser. only_better = 0: lb[r] = v_{j*}, best[r] = j*; 1: only where
 * v_{j*} > lb[r] (then both are replaced). lb float64, best int64, indexed by r. */
static PyObject *lower_rows(PyObject *Py_UNUSED(self), PyObject *args) {
    Py_buffer Cb, Ub, rb, Gb, lbb, bb;
    Py_ssize_t nU, cap, k0, K;
    int only_better;
    if (!PyArg_ParseTuple(args, "y*ny*y*y*nnnw*w*p", &Cb, &nU, &Ub, &rb, &Gb, &cap, &k0, &K, &lbb, &bb,
                          &only_better))
        return NULL;
    PyObject *ret = NULL;
    double *acc = NULL;
    Py_ssize_t nr = rb.len / 8, nk = K - k0;
    if (nk <= 0 || k0 < 0 || K > cap) {
        PyErr_SetString(PyExc_ValueError, "_pointbased_kernel.lower_rows: empty or bad vector range");
        goto done;
    }
    if (!check_len(&Ub, 8, nU, "U")) goto done;
    acc = (double *)malloc(sizeof(double) * (size_t)nk * LOWER_BLOCK);
    if (!acc) { PyErr_NoMemory(); goto done; }
    {
        const double *C = (const double *)Cb.buf, *G = (const double *)Gb.buf;
        const i64 *U = (const i64 *)Ub.buf, *rows = (const i64 *)rb.buf;
        double *lb = (double *)lbb.buf;
        i64 *best = (i64 *)bb.buf;
        Py_ssize_t nC = Cb.len / 8, nG = Gb.len / 8, nlb = lbb.len / 8, nb = bb.len / 8;
        for (Py_ssize_t t = 0; t < nr; t += LOWER_BLOCK) {
            Py_ssize_t n = nr - t < LOWER_BLOCK ? nr - t : LOWER_BLOCK;
            for (Py_ssize_t b = 0; b < n; b++) {
                i64 r = rows[t + b];
                if (r < 0 || (r + 1) * nU > nC || r >= nlb || r >= nb) {
                    PyErr_SetString(PyExc_IndexError, "_pointbased_kernel.lower_rows: row out of range");
                    goto done;
                }
            }
            if (lower_block(C, nU, U, rows + t, n, G, nG, cap, k0, nk, acc) >= 0) {
                PyErr_SetString(PyExc_IndexError, "_pointbased_kernel.lower_rows: state out of range");
                goto done;
            }
            for (Py_ssize_t b = 0; b < n; b++) {
                const double *a = acc + b * nk;
                i64 r = rows[t + b];
                Py_ssize_t jb = 0;
                double vb = a[0];
                for (Py_ssize_t k = 1; k < nk; k++)
                    if (a[k] > vb) { vb = a[k]; jb = k; }
                if (!only_better || vb > lb[r]) { lb[r] = vb; best[r] = k0 + jb; }
            }
        }
    }
    ret = Py_None;
    Py_INCREF(ret);
done:
    free(acc);
    REL(Cb); REL(Ub); REL(rb); REL(Gb); REL(lbb); REL(bb);
    return ret;
}

/* The sawtooth point set (see PointBasedSolver._set_upper), read-only. */
typedef struct {
    const double *Vc, *Q, *pinv, *ev, *delta;
    const i64 *st, *ln, *pr, *ei, *stamp;
    Py_ssize_t A, S, n, nprobe, nent;
} points_t;

/* The upper bound at the belief c (on states U, scattered by pos: pos[U[j]] = j):
 *   base = c.Vc[U];  corr = min(0, min_i lambda_i(c) delta_i) over the points i with
 *   stamp[i] > since,  lambda_i(c) = min_{s in supp b_i} c(s)/b_i(s) (0 when a state of
 *   supp b_i is outside supp c);  returns min(base, max_a c.Qfib[U, a], base + corr) with
 *   with_fib, else base + corr.
 * Branch and bound per point: lambda_i <= c(s)/b_i(s) at the point's probe states, so the
 * minimum over the probes times delta_i (< 0) bounds the correction from below; the point is
 * read in full only when that bound beats the best correction so far, and the read stops as
 * soon as the running minimum cannot beat it any more. The result is the exact minimum.
 * Returns NAN (with the exception set) on a corrupt point set. */
static double sawtooth_row(const double *c, Py_ssize_t nU, const i64 *U, const i64 *pos, const points_t *P,
                           int with_fib, i64 since) {
    double base = 0.0;
    for (Py_ssize_t j = 0; j < nU; j++) base += c[j] * P->Vc[U[j]];
    double ub = INFINITY;
    if (with_fib) {
        double fib = -INFINITY;
        for (Py_ssize_t a = 0; a < P->A; a++) {
            double q = 0.0;
            for (Py_ssize_t j = 0; j < nU; j++) q += c[j] * P->Q[U[j] * P->A + a];
            if (q > fib) fib = q;
        }
        ub = fib < base ? fib : base;
    }
    double corr = 0.0;
    for (Py_ssize_t i = 0; i < P->n; i++) {
        if (P->stamp[i] <= since) continue;
        double d = P->delta[i];
        if (!(d < 0.0)) continue;
        double lam = INFINITY;
        for (Py_ssize_t k = 0; k < P->nprobe; k++) {
            i64 s = P->pr[i * P->nprobe + k];
            if ((unsigned long long)s >= (unsigned long long)P->S) goto corrupt;
            i64 l = pos[s];
            double x = l >= 0 ? c[l] * P->pinv[i * P->nprobe + k] : 0.0;
            if (x < lam) lam = x;
        }
        if (!(lam * d < corr)) continue;
        i64 e0 = P->st[i], e1 = P->st[i] + P->ln[i];
        if (e0 < 0 || e1 > P->nent) goto corrupt;
        for (i64 e = e0; e < e1; e++) {
            if ((unsigned long long)P->ei[e] >= (unsigned long long)P->S) goto corrupt;
            i64 l = pos[P->ei[e]];
            double x = l >= 0 ? c[l] / P->ev[e] : 0.0;
            if (x < lam) {
                lam = x;
                if (!(lam * d < corr)) break;
            }
        }
        double v = lam * d;
        if (v < corr) corr = v;
    }
    double st_ub = base + corr;
    return (with_fib && ub < st_ub) ? ub : st_ub;
corrupt:
    PyErr_SetString(PyExc_IndexError, "_pointbased_kernel: corrupt sawtooth point set");
    return NAN;
}

/* The buffers of a point set, in the argument order "y*y*y*y*y*y*y*y*y*y*nn":
 * Vc, Qfib, pt_start, pt_len, pt_probe, pt_pinv, ent_idx, ent_val, pt_delta, pt_stamp, n, nprobe. */
#define NPB 10
static int points_from(points_t *P, Py_buffer *b, Py_ssize_t n, Py_ssize_t nprobe, Py_ssize_t A, Py_ssize_t S) {
    P->Vc = (const double *)b[0].buf; P->Q = (const double *)b[1].buf;
    P->st = (const i64 *)b[2].buf; P->ln = (const i64 *)b[3].buf; P->pr = (const i64 *)b[4].buf;
    P->pinv = (const double *)b[5].buf; P->ei = (const i64 *)b[6].buf; P->ev = (const double *)b[7].buf;
    P->delta = (const double *)b[8].buf; P->stamp = (const i64 *)b[9].buf;
    P->A = A; P->S = S; P->n = n; P->nprobe = nprobe; P->nent = b[6].len / 8;
    if (!check_len(&b[0], 8, S, "Vc") || !check_len(&b[1], 8, S * A, "Qfib") || !check_len(&b[2], 8, n, "pt_start")
        || !check_len(&b[3], 8, n, "pt_len") || !check_len(&b[4], 8, n * nprobe, "pt_probe")
        || !check_len(&b[5], 8, n * nprobe, "pt_pinv") || !check_len(&b[7], 8, P->nent, "ent_val")
        || !check_len(&b[8], 8, n, "pt_delta") || !check_len(&b[9], 8, n, "pt_stamp"))
        return 0;
    return 1;
}

static int mark(i64 *pos, const i64 *U, Py_ssize_t nU, Py_ssize_t S) {
    for (Py_ssize_t j = 0; j < nU; j++) {
        if (U[j] < 0 || U[j] >= S) {
            for (Py_ssize_t k = 0; k < j; k++) pos[U[k]] = -1;
            PyErr_SetString(PyExc_IndexError, "_pointbased_kernel: state out of range");
            return 0;
        }
        pos[U[j]] = j;
    }
    return 1;
}

static void unmark(i64 *pos, const i64 *U, Py_ssize_t nU) {
    for (Py_ssize_t j = 0; j < nU; j++) pos[U[j]] = -1;
}

/* sawtooth(C, nU, U, rows, with_fib, since, pos, <point set>, A, out) -> None
 * out[t] = sawtooth_row(C[rows[t]]) (C float64 [*, nU] row-major). pos: int64 [S] scratch,
 * all -1 on entry and on exit. */
static PyObject *sawtooth(PyObject *Py_UNUSED(self), PyObject *args) {
    Py_buffer Cb, Ub, rb, pb, ob, b[NPB];
    Py_ssize_t nU, n, nprobe, A;
    int with_fib;
    long long since;
    if (!PyArg_ParseTuple(args, "y*ny*y*pLw*y*y*y*y*y*y*y*y*y*y*nnnw*", &Cb, &nU, &Ub, &rb, &with_fib, &since, &pb,
                          &b[0], &b[1], &b[2], &b[3], &b[4], &b[5], &b[6], &b[7], &b[8], &b[9], &n, &nprobe, &A, &ob))
        return NULL;
    PyObject *ret = NULL;
    points_t P;
    Py_ssize_t S = pb.len / 8, nr = rb.len / 8, nC = Cb.len / 8;
    const i64 *U = (const i64 *)Ub.buf, *rows = (const i64 *)rb.buf;
    i64 *pos = (i64 *)pb.buf;
    if (!points_from(&P, b, n, nprobe, A, S) || !check_len(&Ub, 8, nU, "U") || !check_len(&ob, 8, nr, "out"))
        goto done;
    for (Py_ssize_t t = 0; t < nr; t++)
        if (rows[t] < 0 || (rows[t] + 1) * nU > nC) { PyErr_SetString(PyExc_IndexError, "_pointbased_kernel.sawtooth: row out of range"); goto done; }
    if (!mark(pos, U, nU, S)) goto done;
    {
        double *out = (double *)ob.buf;
        for (Py_ssize_t t = 0; t < nr; t++) {
            out[t] = sawtooth_row((const double *)Cb.buf + rows[t] * nU, nU, U, pos, &P, with_fib, since);
            if (PyErr_Occurred()) break;
        }
    }
    unmark(pos, U, nU);
    if (!PyErr_Occurred()) { ret = Py_None; Py_INCREF(ret); }
done:
    REL(Cb); REL(Ub); REL(rb); REL(pb); REL(ob);
    for (int k = 0; k < NPB; k++) REL(b[k]);
    return ret;
}

/* refresh_upper(Rb, p, ub_c, seen, C, nU, U, live, g, A, Z, ub_version, vc_version, pos, <point set>, Qu) -> a
 *
 * PointBasedSolver._refresh_upper: Qu[a] = Rb[a] + g sum_o p[a,o] ub_c[a,o]; while the greedy
 * action a (first maximiser) has not been refreshed in this call: re-read the sawtooth at its
 * live successors (all points and the FIB vectors when a corner value fell since seen[a], else
 * only the points stamped after seen[a]; nothing when seen[a] == ub_version), lower ub_c[a, .]
 * to it, set seen[a] = ub_version, recompute Qu. Returns the final greedy action; Qu holds the
 * upper-bound Q-values. Rb, p float64 [A] / [A, Z]; ub_c float64 [A, Z] and seen int64 [A]
 * updated in place; live int64 ascending. */
static PyObject *refresh_upper(PyObject *Py_UNUSED(self), PyObject *args) {
    Py_buffer Rbb, pbb, ubb, sb, Cb, Ub, lb, posb, qb, b[NPB];
    Py_ssize_t nU, A, Z, n, nprobe;
    double g;
    long long ubv, vcv;
    if (!PyArg_ParseTuple(args, "y*y*w*w*y*ny*y*dnnLLw*y*y*y*y*y*y*y*y*y*y*nnw*", &Rbb, &pbb, &ubb, &sb, &Cb, &nU, &Ub,
                          &lb, &g, &A, &Z, &ubv, &vcv, &posb, &b[0], &b[1], &b[2], &b[3], &b[4], &b[5], &b[6], &b[7],
                          &b[8], &b[9], &n, &nprobe, &qb))
        return NULL;
    PyObject *ret = NULL;
    char *done = NULL;
    points_t P;
    Py_ssize_t S = posb.len / 8, nl = lb.len / 8, nC = Cb.len / 8;
    const i64 *U = (const i64 *)Ub.buf, *live = (const i64 *)lb.buf;
    i64 *pos = (i64 *)posb.buf, *seen = (i64 *)sb.buf;
    const double *Rb = (const double *)Rbb.buf, *p = (const double *)pbb.buf, *C = (const double *)Cb.buf;
    double *ub = (double *)ubb.buf, *Qu = (double *)qb.buf;
    if (!points_from(&P, b, n, nprobe, A, S) || !check_len(&Rbb, 8, A, "Rb") || !check_len(&pbb, 8, A * Z, "p")
        || !check_len(&ubb, 8, A * Z, "ub_c") || !check_len(&sb, 8, A, "seen") || !check_len(&Ub, 8, nU, "U")
        || !check_len(&qb, 8, A, "Qu"))
        goto done;
    for (Py_ssize_t t = 0; t < nl; t++)
        if (live[t] < 0 || live[t] >= A * Z || (live[t] + 1) * nU > nC) { PyErr_SetString(PyExc_IndexError, "_pointbased_kernel.refresh_upper: bad live row"); goto done; }
    done = (char *)calloc((size_t)A, 1);
    if (!done) { PyErr_NoMemory(); goto done; }
    if (!mark(pos, U, nU, S)) goto done;
    {
        Py_ssize_t a;
        for (;;) {
            a = 0;
            for (Py_ssize_t x = 0; x < A; x++) {
                double q = 0.0;
                for (Py_ssize_t o = 0; o < Z; o++) q += p[x * Z + o] * ub[x * Z + o];
                Qu[x] = Rb[x] + g * q;
                if (Qu[x] > Qu[a]) a = x;
            }
            if (done[a]) break;
            done[a] = 1;
            if (seen[a] < ubv) {
                int full = seen[a] < vcv;
                for (Py_ssize_t t = 0; t < nl; t++) {
                    i64 r = live[t];
                    if (r < a * Z || r >= (a + 1) * Z) continue;
                    double v = sawtooth_row(C + r * nU, nU, U, pos, &P, full, full ? -1 : seen[a]);
                    if (PyErr_Occurred()) goto unmark_;
                    if (v < ub[r]) ub[r] = v;
                }
            }
            seen[a] = ubv;
        }
        ret = PyLong_FromSsize_t(a);
    }
unmark_:
    unmark(pos, U, nU);
done:
    free(done);
    REL(Rbb); REL(pbb); REL(ubb); REL(sb); REL(Cb); REL(Ub); REL(lb); REL(posb); REL(qb);
    for (int k = 0; k < NPB; k++) REL(b[k]);
    return ret;
}

/* alpha(a, best_a, R, O, GT, cap, tv_ptr, tv_ind, tv_dat, S, A, Z, g, inner, out) -> None
 *
 * The backed-up vector out[s] = R[s, a] + g * sum_{s'} T[a][s, s'] inner[s'] with
 * inner[s'] = sum_o O[a, s', o] GT[s', best_a[o]] (R float64 [S, A]; O float64 [A, S, Z];
 * GT float64 [S, cap]; T as one CSR (A*S) x S block, row a*S+s = T[a][s, :]; inner float64 [S]
 * scratch; out float64 [S]). */
static PyObject *alpha(PyObject *Py_UNUSED(self), PyObject *args) {
    Py_buffer bb, Rb, Ob, Gb, pb, ib, db, innb, ob;
    Py_ssize_t a, cap, S, A, Z;
    double g;
    if (!PyArg_ParseTuple(args, "ny*y*y*y*ny*y*y*nnndw*w*", &a, &bb, &Rb, &Ob, &Gb, &cap, &pb, &ib, &db, &S, &A, &Z,
                          &g, &innb, &ob))
        return NULL;
    PyObject *ret = NULL;
    if (a < 0 || a >= A || !check_len(&bb, 8, Z, "best_a") || !check_len(&Rb, 8, S * A, "R")
        || !check_len(&Ob, 8, A * S * Z, "O") || !check_len(&Gb, 8, S * cap, "GT") || !check_len(&pb, 8, A * S + 1, "tv_ptr")
        || !check_len(&innb, 8, S, "inner") || !check_len(&ob, 8, S, "out"))
        goto done;
    {
        const i64 *best = (const i64 *)bb.buf, *tp = (const i64 *)pb.buf, *ti = (const i64 *)ib.buf;
        const double *R = (const double *)Rb.buf, *O = (const double *)Ob.buf + a * S * Z, *G = (const double *)Gb.buf;
        const double *td = (const double *)db.buf;
        double *inner = (double *)innb.buf, *out = (double *)ob.buf;
        Py_ssize_t nti = ib.len / 8;
        for (Py_ssize_t o = 0; o < Z; o++)
            if (best[o] < 0 || best[o] >= cap) { PyErr_SetString(PyExc_IndexError, "_pointbased_kernel.alpha: vector out of range"); goto done; }
        for (Py_ssize_t s = 0; s < S; s++) {
            const double *Os = O + s * Z, *Gs = G + s * cap;
            double x = 0.0;
            for (Py_ssize_t o = 0; o < Z; o++) x += Os[o] * Gs[best[o]];
            inner[s] = x;
        }
        const i64 *row = tp + a * S;
        for (Py_ssize_t s = 0; s < S; s++) {
            double x = 0.0;
            for (i64 e = row[s]; e < row[s + 1]; e++) {
                if (e < 0 || e >= nti || ti[e] < 0 || ti[e] >= S) { PyErr_SetString(PyExc_IndexError, "_pointbased_kernel.alpha: bad T"); goto done; }
                x += td[e] * inner[ti[e]];
            }
            out[s] = R[s * A + a] + g * x;
        }
    }
    ret = Py_None;
    Py_INCREF(ret);
done:
    REL(bb); REL(Rb); REL(Ob); REL(Gb); REL(pb); REL(ib); REL(db); REL(innb); REL(ob);
    return ret;
}

/* qvalue(Rb, p, X, g, A, Z) -> (a, q)
 * Q[a] = Rb[a] + g sum_o p[a,o] X[a,o] (Rb float64 [A], p and X float64 [A, Z]); returns the first
 * maximiser and its value. */
static PyObject *qvalue(PyObject *Py_UNUSED(self), PyObject *args) {
    Py_buffer Rbb, pbb, xb;
    double g;
    Py_ssize_t A, Z;
    if (!PyArg_ParseTuple(args, "y*y*y*dnn", &Rbb, &pbb, &xb, &g, &A, &Z)) return NULL;
    PyObject *ret = NULL;
    if (A >= 1 && check_len(&Rbb, 8, A, "Rb") && check_len(&pbb, 8, A * Z, "p") && check_len(&xb, 8, A * Z, "X")) {
        const double *Rb = (const double *)Rbb.buf, *p = (const double *)pbb.buf, *X = (const double *)xb.buf;
        Py_ssize_t best = 0;
        double qb = -INFINITY;
        for (Py_ssize_t a = 0; a < A; a++) {
            double q = 0.0;
            for (Py_ssize_t o = 0; o < Z; o++) q += p[a * Z + o] * X[a * Z + o];
            q = Rb[a] + g * q;
            if (a == 0 || q > qb) { qb = q; best = a; }
        }
        ret = Py_BuildValue("nd", best, qb);
    } else if (!PyErr_Occurred()) {
        PyErr_SetString(PyExc_ValueError, "_pointbased_kernel.qvalue: no actions");
    }
    REL(Rbb); REL(pbb); REL(xb);
    return ret;
}

/* excess_obs(p, ub_c, lb, jitter, a, thr, Z) -> o
 * The first maximiser over o of p[a,o] (ub_c[a,o] - lb[a,o] - thr) + jitter[o] (the trial's
 * weighted excess uncertainty, ties broken by the seeded jitter). */
static PyObject *excess_obs(PyObject *Py_UNUSED(self), PyObject *args) {
    Py_buffer pbb, ub, lbb, jb;
    Py_ssize_t a, Z;
    double thr;
    if (!PyArg_ParseTuple(args, "y*y*y*y*ndn", &pbb, &ub, &lbb, &jb, &a, &thr, &Z)) return NULL;
    PyObject *ret = NULL;
    if (Z >= 1 && a >= 0 && check_len(&pbb, 8, (a + 1) * Z, "p") && check_len(&ub, 8, (a + 1) * Z, "ub_c")
        && check_len(&lbb, 8, (a + 1) * Z, "lb") && check_len(&jb, 8, Z, "jitter")) {
        const double *p = (const double *)pbb.buf + a * Z, *u = (const double *)ub.buf + a * Z;
        const double *l = (const double *)lbb.buf + a * Z, *j = (const double *)jb.buf;
        Py_ssize_t best = 0;
        double sb = -INFINITY;
        for (Py_ssize_t o = 0; o < Z; o++) {
            double x = p[o] * (u[o] - l[o] - thr) + j[o];
            if (o == 0 || x > sb) { sb = x; best = o; }
        }
        ret = PyLong_FromSsize_t(best);
    } else if (!PyErr_Occurred()) {
        PyErr_SetString(PyExc_ValueError, "_pointbased_kernel.excess_obs: bad action or no observations");
    }
    REL(pbb); REL(ub); REL(lbb); REL(jb);
    return ret;
}

static PyMethodDef methods[] = {
    {"qvalue", qvalue, METH_VARARGS, "Greedy action and value of Rb + g sum_o p X."},
    {"excess_obs", excess_obs, METH_VARARGS, "The trial's observation: largest weighted excess uncertainty."},
    {"alpha", alpha, METH_VARARGS, "The point-based backup's new vector from the maximising successor vectors."},
    {"successors", successors, METH_VARARGS, "Successor beliefs of one belief under every (action, observation)."},
    {"lower_rows", lower_rows, METH_VARARGS, "Lower bound and maximising vector at rows of successor beliefs."},
    {"sawtooth", sawtooth, METH_VARARGS, "Sawtooth upper bound at rows of successor beliefs (branch and bound)."},
    {"refresh_upper", refresh_upper, METH_VARARGS, "Re-read the sawtooth at the greedy action's successors until it settles."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_pointbased_kernel",
                                    "Inner loops of pearl_pomdp.solvers.point_based (see the C source).", -1, methods,
                                    NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__pointbased_kernel(void) { return PyModule_Create(&module); }

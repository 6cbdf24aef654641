/* The point-based solver's whole search in C (engine="c" of solve_point_based).
 *
 * HSVI2 (Smith & Simmons, UAI 2005) with the Python engine's bounds: the lower bound is a set
 * of alpha-vectors (each a lower bound on the value of a policy), the upper bound the FIB vectors
 * together with a point set read by sawtooth interpolation over the corner values
 * V_c(s) = max_a Q_FIB(s, a). Both start bounds are computed here too (FIB from Rmax/(1-g)
 * downwards, the blind policies from below), so a small file costs no Python set-up.
 * A trial walks from b0 taking the action with the best upper bound and the observation with
 * the largest weighted excess width P(o|b,a)(UB - LB - eps_t g^-(d+1)); it stops where the width
 * is within eps_t g^-d, eps_t = max(eps, kappa gap(b0)) while the gap is over 10 eps, eps/2
 * after (the Python engine's rule). Every belief on the way down and again on the way back gets
 * one lower-bound backup (a new vector when it raises LB there; vectors it dominates pointwise
 * leave) and one upper-bound backup (a new sawtooth point when it lowers UB there).
 *
 * Beliefs are dense arrays with a support list; T is read from the (A*S) x S CSR block whose row
 * a*S + s is T[a][s, :]. Everything is deterministic: no seed is used (ties go to the lowest
 * index). Only Python's C API and the buffer protocol are used (no numpy headers).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

typedef int64_t i64;

static double now_s(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

typedef struct {
    Py_ssize_t S, A, Z;
    double g;
    const double *R, *O, *b0;              /* R[s*A+a], O[(a*S+s')*Z+o] */
    const double *Q;                         /* Q_FIB[s*A+a] */
    const i64 *tp, *ti;                      /* (A*S) x S CSR */
    const double *td;
    double *Vc;                              /* corner values */
    /* lower bound */
    /* Gamma stored state-major, al[s*Kcap + k] = alpha_k(s): the lower bound at a belief reads one
     * contiguous row per state of its support (vector-major rows of 100 kB each on RockSample[7,8]
     * made best_alpha 64 % of a run, all cache misses). kacc: K partial sums. */
    double *al, *kacc; i64 *act; Py_ssize_t K, Kcap;
    /* upper bound points: sparse beliefs */
    i64 *pidx; double *pval; Py_ssize_t pn, pcap;        /* entries */
    i64 *pstart, *plen; double *pdelta, *pv; Py_ssize_t np_, npcap;
    /* The visited beliefs are the points (one entry per distinct belief, found by its hash;
     * pdelta = +inf until a backup lowers UB there), so a belief seen again lowers its own
     * point instead of adding one. */
    uint64_t *phash; i64 *htab; Py_ssize_t hcap;
    char *keep;                              /* scratch of prune_alphas */
    double deadline;                         /* the time limit, on now_s()'s clock */
    Py_ssize_t K_pruned;                     /* |Gamma| after the last prune */
    double *db;                              /* a dense belief (zero between uses) */
    long ub_sweeps, ub_sweep_backups, lb_sweep_backups;
    /* Cached upper bounds at each entry's successors (A*Z slots, then one for the entry itself),
     * read at log position uver[p]; plog lists the points in the order their values fell, so a
     * cached bound is refreshed from the points that fell since (upper bounds only fall: the
     * cached value stays valid), as the Python engine's versioned sawtooth reads. */
    double *ucache; i64 *uver; Py_ssize_t ucap;
    i64 *pact;                               /* per entry: the action of its last LB backup (-1: none) */
    i64 *plog; Py_ssize_t plogn, plogcap;
    /* A corner value fell at log position vc_logpos (every delta moved): a cache read before it
     * is re-read in full. */
    Py_ssize_t vc_logpos; long corner_updates;
    /* Each point's entries again, most likely state first, with 1/b_i(s): the sawtooth's ratio
     * min_s b(s)/b_i(s) is usually set by b_i's likely states, so its branch and bound stops
     * early (the Python engine's probe states). */
    i64 *sidx; double *sinv; Py_ssize_t scap;
    /* scratch */
    double *bt; i64 *btnz; char *mark;       /* b T_a, support */
    double *succ; i64 *snz; Py_ssize_t *sn; double *sp;  /* per o successor, support, count, prob */
    double *w;
    long backups;
} ctx_t;

static int grow(void **p, Py_ssize_t *cap, Py_ssize_t need, size_t item) {
    if (need <= *cap) return 0;
    Py_ssize_t c = *cap ? *cap : 64;
    while (c < need) c *= 2;
    void *q = realloc(*p, (size_t)c * item);
    if (!q) { PyErr_NoMemory(); return -1; }
    *p = q; *cap = c;
    return 0;
}

static double dot_nz(const double *v, const double *b, const i64 *nz, Py_ssize_t n) {
    double s = 0.0;
    for (Py_ssize_t i = 0; i < n; i++) s += v[nz[i]] * b[nz[i]];
    return s;
}

/* The first k maximising sum_i w_i alpha_k(ix_i) (w_i = b[ix_i] when dense, else w[i]); its value in *val. */
static Py_ssize_t best_k(const ctx_t *c, const i64 *ix, const double *w, const double *dense, Py_ssize_t n,
                         double *val) {
    Py_ssize_t K = c->K, Kc = c->Kcap, best = 0;
    double *acc = c->kacc, bv = -INFINITY;
    for (Py_ssize_t k = 0; k < K; k++) acc[k] = 0.0;
    for (Py_ssize_t i = 0; i < n; i++) {
        double wi = dense ? dense[ix[i]] : w[i];
        if (wi == 0.0) continue;
        const double *row = c->al + ix[i] * Kc;
        for (Py_ssize_t k = 0; k < K; k++) acc[k] += wi * row[k];
    }
    for (Py_ssize_t k = 0; k < K; k++) if (acc[k] > bv) { bv = acc[k]; best = k; }
    *val = bv;
    return best;
}

static Py_ssize_t best_alpha(const ctx_t *c, const double *b, const i64 *nz, Py_ssize_t n, double *val) {
    return best_k(c, nz, NULL, b, n, val);
}

/* min(best, phi_p delta_p) for sawtooth point p at b: phi_p = min over its entries of b(s)/b_p(s),
 * read most likely state first so the scan stops once phi_p delta_p can no longer beat best. */
static inline double point_drop(const ctx_t *c, i64 p, const double *b, double best) {
    double d = c->pdelta[p];
    if (d >= best) return best;
    const i64 *ix = c->sidx + c->pstart[p]; const double *iv = c->sinv + c->pstart[p];
    double phi = INFINITY;
    for (i64 j = 0; j < c->plen[p]; j++) {
        double r = b[ix[j]] * iv[j];
        if (r < phi) { phi = r; if (phi * d >= best) break; }
    }
    return phi * d < best ? phi * d : best;
}

static double upper(const ctx_t *c, const double *b, const i64 *nz, Py_ssize_t n) {
    Py_ssize_t A = c->A;
    double fib;
    fib = -INFINITY;   /* FIB: max over a of b.Q(:,a) */
    for (Py_ssize_t a = 0; a < A; a++) {
        double v = 0.0;
        for (Py_ssize_t i = 0; i < n; i++) v += b[nz[i]] * c->Q[nz[i] * A + a];
        if (v > fib) fib = v;
    }
    double base = dot_nz(c->Vc, b, nz, n), best = 0.0;
    for (Py_ssize_t p = 0; p < c->np_; p++) best = point_drop(c, p, b, best);
    double saw = base + best;
    return saw < fib ? saw : fib;
}

/* Successors of belief b under action a: sn[o], snz, succ (normalised), sp[o] = P(o|b,a). */
static void successors(ctx_t *c, const double *b, const i64 *nz, Py_ssize_t n, Py_ssize_t a) {
    Py_ssize_t S = c->S, Z = c->Z, m = 0;
    for (Py_ssize_t i = 0; i < n; i++) {
        i64 s = nz[i]; double bs = b[s];
        i64 r = a * S + s;
        for (i64 k = c->tp[r]; k < c->tp[r + 1]; k++) {
            i64 t = c->ti[k];
            if (!c->mark[t]) { c->mark[t] = 1; c->btnz[m++] = t; c->bt[t] = 0.0; }
            c->bt[t] += bs * c->td[k];
        }
    }
    for (Py_ssize_t o = 0; o < Z; o++) { c->sn[o] = 0; c->sp[o] = 0.0; }
    for (Py_ssize_t i = 0; i < m; i++) {
        i64 t = c->btnz[i]; double v = c->bt[t];
        c->mark[t] = 0;
        const double *Oz = c->O + (a * S + t) * Z;
        for (Py_ssize_t o = 0; o < Z; o++) {
            double q = v * Oz[o];
            if (q > 0.0) {
                c->succ[o * S + t] = q;
                c->snz[o * S + c->sn[o]++] = t;
                c->sp[o] += q;
            }
        }
    }
    for (Py_ssize_t o = 0; o < Z; o++) {
        double p = c->sp[o];
        if (p <= 0.0) continue;
        for (Py_ssize_t i = 0; i < c->sn[o]; i++) c->succ[o * S + c->snz[o * S + i]] /= p;
    }
    c->btnz[S] = m;   /* support size of b T_a, for the vector's product */
}

static void clear_succ(ctx_t *c) {
    for (Py_ssize_t o = 0; o < c->Z; o++)
        for (Py_ssize_t i = 0; i < c->sn[o]; i++) c->succ[o * c->S + c->snz[o * c->S + i]] = 0.0;
}

/* Drop the columns j of Gamma with keep[j] == 0 (keeping the order of the rest). */
static void compact_alphas(ctx_t *c, const char *keep) {
    Py_ssize_t S = c->S, Kc = c->Kcap, K = c->K, k = 0;
    for (Py_ssize_t j = 0; j < K; j++) if (keep[j]) c->act[k++] = c->act[j];
    if (k == K) return;
    for (Py_ssize_t s = 0; s < S; s++) {
        double *row = c->al + s * Kc;
        Py_ssize_t m = 0;
        for (Py_ssize_t j = 0; j < K; j++) if (keep[j]) row[m++] = row[j];
    }
    c->K = k;
}

#define DOMINANCE_MAX_S 64

static int add_alpha(ctx_t *c, const double *v, i64 a) {
    Py_ssize_t S = c->S, K = c->K, Kc = c->Kcap;
    /* Drop the vectors the new one dominates pointwise, on small models only: prune_alphas drops
     * them anyway, and the test's strided reads cost a quarter of a RockSample[7,8] run (LB 20.83
     * instead of 21.15 after 20 s) and 15 % on RockSample[4,4], while they save 10-30 % on the
     * files with at most DOMINANCE_MAX_S states (web-ad, paint, 4x3, tiger, stand-tiger). */
    Py_ssize_t cap = 0;
    if (K > 0 && S <= DOMINANCE_MAX_S) {
        if (grow((void **)&c->keep, &cap, K, 1) < 0) return -1;
        for (Py_ssize_t j = 0; j < K; j++) {
            Py_ssize_t s = 0;
            while (s < S && c->al[s * Kc + j] <= v[s]) s++;
            c->keep[j] = s < S;
        }
        compact_alphas(c, c->keep);
        K = c->K;
    }
    if (K + 1 > Kc) {
        Py_ssize_t nc = Kc ? 2 * Kc : 64;
        double *al = malloc((size_t)S * (size_t)nc * sizeof(double));
        double *acc = realloc(c->kacc, (size_t)nc * sizeof(double));
        if (acc) c->kacc = acc;
        i64 *act = acc ? realloc(c->act, (size_t)nc * sizeof(i64)) : NULL;
        if (act) c->act = act;
        if (!al || !acc || !act) { free(al); PyErr_NoMemory(); return -1; }
        if (K > 0)   /* (c->al is NULL before the first vector) */
            for (Py_ssize_t s = 0; s < S; s++) memcpy(al + s * nc, c->al + s * Kc, (size_t)K * sizeof(double));
        free(c->al);
        c->al = al; c->Kcap = Kc = nc;
    }
    for (Py_ssize_t s = 0; s < S; s++) c->al[s * Kc + K] = v[s];
    c->act[K] = a;
    c->K = K + 1;
    return 0;
}

static uint64_t belief_hash(const double *b, const i64 *nz, Py_ssize_t n) {
    uint64_t h = 1469598103934665603ULL;     /* FNV-1a over (state, bits of b(state)) */
    for (Py_ssize_t i = 0; i < n; i++) {
        double v = b[nz[i]];
        if (v <= 0.0) continue;
        uint64_t bits; memcpy(&bits, &v, sizeof bits);
        h = (h ^ (uint64_t)nz[i]) * 1099511628211ULL;
        h = (h ^ bits) * 1099511628211ULL;
    }
    return h ^ (h >> 29);
}

static int rehash(ctx_t *c, Py_ssize_t cap) {
    i64 *t = malloc((size_t)cap * sizeof(i64));
    if (!t) { PyErr_NoMemory(); return -1; }
    for (Py_ssize_t i = 0; i < cap; i++) t[i] = -1;
    for (Py_ssize_t p = 0; p < c->np_; p++) {
        Py_ssize_t j = (Py_ssize_t)(c->phash[p] & (uint64_t)(cap - 1));
        while (t[j] >= 0) j = (j + 1) & (cap - 1);
        t[j] = p;
    }
    free(c->htab); c->htab = t; c->hcap = cap;
    return 0;
}

/* The entry of belief b (added, with no upper-bound value yet, when b is new): its index, or -1
 * on a memory error. Beliefs match when their supports and values are bitwise equal (a trial
 * that follows the same actions and observations computes the same belief the same way; merging
 * beliefs equal up to rounding, as the Python engine's graph does, made web-ad and paint stall). */
static Py_ssize_t belief_entry(ctx_t *c, const double *b, const i64 *nz, Py_ssize_t n) {
    uint64_t h = belief_hash(b, nz, n);
    Py_ssize_t m = 0;
    for (Py_ssize_t i = 0; i < n; i++) if (b[nz[i]] > 0.0) m++;
    if (c->hcap) {
        Py_ssize_t j = (Py_ssize_t)(h & (uint64_t)(c->hcap - 1));
        for (; c->htab[j] >= 0; j = (j + 1) & (c->hcap - 1)) {
            i64 p = c->htab[j];
            if (c->phash[p] != h || c->plen[p] != m) continue;
            const i64 *ix = c->pidx + c->pstart[p]; const double *vx = c->pval + c->pstart[p];
            Py_ssize_t k = 0, i = 0;
            for (; i < n && k <= m; i++) {
                if (!(b[nz[i]] > 0.0)) continue;
                if (k == m || ix[k] != nz[i] || vx[k] != b[nz[i]]) break;
                k++;
            }
            if (i == n && k == m) return (Py_ssize_t)p;
        }
    }
    if (2 * (c->np_ + 1) > c->hcap && rehash(c, c->hcap ? 2 * c->hcap : 1024) < 0) return -1;
    Py_ssize_t cap = c->npcap;
    if (grow((void **)&c->pstart, &cap, c->np_ + 1, sizeof(i64)) < 0) return -1;
    cap = c->npcap;
    if (grow((void **)&c->plen, &cap, c->np_ + 1, sizeof(i64)) < 0) return -1;
    cap = c->npcap;
    if (grow((void **)&c->pdelta, &cap, c->np_ + 1, sizeof(double)) < 0) return -1;
    cap = c->npcap;
    if (grow((void **)&c->pv, &cap, c->np_ + 1, sizeof(double)) < 0) return -1;
    cap = c->npcap;
    if (grow((void **)&c->phash, &cap, c->np_ + 1, sizeof(uint64_t)) < 0) return -1;
    c->npcap = cap;
    cap = c->pcap;
    if (grow((void **)&c->pidx, &cap, c->pn + m, sizeof(i64)) < 0) return -1;
    cap = c->pcap;
    if (grow((void **)&c->pval, &cap, c->pn + m, sizeof(double)) < 0) return -1;
    c->pcap = cap;
    cap = c->scap;
    if (grow((void **)&c->sidx, &cap, c->pn + m, sizeof(i64)) < 0) return -1;
    cap = c->scap;
    if (grow((void **)&c->sinv, &cap, c->pn + m, sizeof(double)) < 0) return -1;
    c->scap = cap;
    Py_ssize_t k = 0;
    for (Py_ssize_t i = 0; i < n; i++)
        if (b[nz[i]] > 0.0) { c->pidx[c->pn + k] = nz[i]; c->pval[c->pn + k] = b[nz[i]]; k++; }
    i64 *si = c->sidx + c->pn; double *sv = c->sinv + c->pn;
    for (Py_ssize_t i = 0; i < m; i++) {      /* insertion sort by b_i(s) descending (stable) */
        i64 s = c->pidx[c->pn + i]; double v = c->pval[c->pn + i];
        Py_ssize_t j = i;
        while (j > 0 && 1.0 / sv[j - 1] < v) { si[j] = si[j - 1]; sv[j] = sv[j - 1]; j--; }
        si[j] = s; sv[j] = 1.0 / v;
    }
    Py_ssize_t p = c->np_;
    if (c->np_ + 1 > c->ucap) {
        Py_ssize_t nc = c->ucap ? 2 * c->ucap : 256;
        double *uc = realloc(c->ucache, (size_t)nc * (size_t)(c->A * c->Z + 1) * sizeof(double));
        if (!uc) { PyErr_NoMemory(); return -1; }
        c->ucache = uc;
        i64 *uv = realloc(c->uver, (size_t)nc * sizeof(i64));
        if (!uv) { PyErr_NoMemory(); return -1; }
        c->uver = uv;
        i64 *pa = realloc(c->pact, (size_t)nc * sizeof(i64));
        if (!pa) { PyErr_NoMemory(); return -1; }
        c->pact = pa; c->ucap = nc;
    }
    c->uver[p] = -1; c->pact[p] = -1;
    c->pstart[p] = c->pn; c->plen[p] = m; c->pdelta[p] = INFINITY; c->pv[p] = INFINITY; c->phash[p] = h;
    c->pn += m; c->np_++;
    Py_ssize_t j = (Py_ssize_t)(h & (uint64_t)(c->hcap - 1));
    while (c->htab[j] >= 0) j = (j + 1) & (c->hcap - 1);
    c->htab[j] = p;
    return p;
}

/* Lower the upper bound at belief entry p to v (a sawtooth point: its excess over b.V_c). At a
 * corner (a belief on one state s) the corner value V_c(s) itself falls, and with it the base
 * b.V_c of every read: the sawtooth then adds the corner's gain to the best point's instead of
 * taking the better of the two (HSVI2's corner update, as the Python engine's _set_upper; on
 * 4x5x2, whose beliefs often collapse to one cell, it cut the trials to the gap threefold). */
static int set_point(ctx_t *c, Py_ssize_t p, double v) {
    const i64 *ix = c->pidx + c->pstart[p]; const double *vx = c->pval + c->pstart[p];
    if (c->plen[p] == 1) {
        i64 s = ix[0];
        if (!(v < c->Vc[s] - 1e-12 * (1.0 + fabs(c->Vc[s])))) return 0;
        c->Vc[s] = v;
        c->pv[p] = v;
        for (Py_ssize_t q = 0; q < c->np_; q++) {
            if (c->pv[q] == INFINITY) continue;
            const i64 *iq = c->pidx + c->pstart[q]; const double *vq = c->pval + c->pstart[q];
            double base = 0.0;
            for (i64 j = 0; j < c->plen[q]; j++) base += c->Vc[iq[j]] * vq[j];
            c->pdelta[q] = c->pv[q] - base;
        }
        if (grow((void **)&c->plog, &c->plogcap, c->plogn + 1, sizeof(i64)) < 0) return -1;
        c->plog[c->plogn++] = p;
        c->vc_logpos = c->plogn;
        c->corner_updates++;
        return 0;
    }
    double base = 0.0;
    for (i64 j = 0; j < c->plen[p]; j++) base += c->Vc[ix[j]] * vx[j];
    if (v - base < c->pdelta[p]) {
        c->pdelta[p] = v - base;
        c->pv[p] = v;
        if (grow((void **)&c->plog, &c->plogcap, c->plogn + 1, sizeof(i64)) < 0) return -1;
        c->plog[c->plogn++] = p;
    }
    return 0;
}

/* min(cur, b.V_c + min over the points logged from position `from` of phi_i delta_i): a cached
 * upper bound cur at b refreshed from the points whose values fell since it was read. */
static double upper_since(const ctx_t *c, const double *b, const i64 *nz, Py_ssize_t n, Py_ssize_t from,
                          double cur) {
    double base = dot_nz(c->Vc, b, nz, n), best = cur - base;
    for (Py_ssize_t q = from; q < c->plogn; q++) best = point_drop(c, c->plog[q], b, best);
    return base + best;
}

/* The upper bound at a belief read through entry p's cache slot (refreshed from the log since
 * ver, or read in full when that is no cheaper or there is no cached value). */
static double cached_upper(ctx_t *c, Py_ssize_t p, i64 ver, Py_ssize_t slot, const double *b, const i64 *nz,
                           Py_ssize_t n) {
    double *uc = c->ucache + p * (c->A * c->Z + 1) + slot;
    double v;
    if (ver >= 0 && ver >= c->vc_logpos && c->plogn - ver < c->np_) v = upper_since(c, b, nz, n, (Py_ssize_t)ver, *uc);
    else {
        v = upper(c, b, nz, n);
        if (ver >= 0 && *uc < v) v = *uc;   /* (both are upper bounds) */
    }
    *uc = v;
    return v;
}

/* Keep the vectors that are maximal at some visited belief (the first maximiser, as best_alpha
 * picks) or at one of its successors under the action its last lower-bound backup took, dropping
 * the rest: the lower bound at every visited belief is unchanged, and b0 is one of them. (Vectors
 * that serve only successors carry the lower bound there: without them TagAvoid's lower bound
 * stalled, -6.7 instead of -6.1 after 20 s; those of every action's successors, marked as the
 * backups used them, kept hallway's Gamma ten times larger.) Pays one product with Gamma per visited belief, so it waits until |Gamma| has
 * doubled (see the trial loop). */
static int prune_alphas(ctx_t *c) {
    Py_ssize_t S = c->S, cap = 0;
    if (grow((void **)&c->keep, &cap, c->K, 1) < 0) return -1;
    memset(c->keep, 0, (size_t)c->K);
    i64 *sup = malloc((size_t)S * sizeof(i64));
    if (!sup) { PyErr_NoMemory(); return -1; }
    for (Py_ssize_t p = 0; p < c->np_; p++) {
        const i64 *ix = c->pidx + c->pstart[p]; const double *vx = c->pval + c->pstart[p];
        double bv;
        c->keep[best_k(c, ix, vx, NULL, (Py_ssize_t)c->plen[p], &bv)] = 1;
        if (c->pact[p] < 0) continue;
        /* and at its successors under the action its last lower-bound backup took */
        Py_ssize_t n = (Py_ssize_t)c->plen[p];
        for (Py_ssize_t j = 0; j < n; j++) { c->db[ix[j]] = vx[j]; sup[j] = ix[j]; }
        successors(c, c->db, sup, n, (Py_ssize_t)c->pact[p]);
        for (Py_ssize_t o = 0; o < c->Z; o++)
            if (c->sp[o] > 0.0) c->keep[best_alpha(c, c->succ + o * S, c->snz + o * S, c->sn[o], &bv)] = 1;
        clear_succ(c);
        for (Py_ssize_t j = 0; j < n; j++) c->db[sup[j]] = 0.0;
    }
    free(sup);
    compact_alphas(c, c->keep);
    c->K_pruned = c->K;
    return 0;
}

/* One backup at b: both bounds updated there. Returns the best action by the upper bound
 * (before this backup's points) and, through *o_out, the observation with the largest weighted
 * excess width at depth+1 (threshold thr); lb_out and ub_out: the bounds at b after the backup. */
static int backup(ctx_t *c, const double *b, const i64 *nz, Py_ssize_t n, double thr, int with_upper,
                  Py_ssize_t *a_out, Py_ssize_t *o_out, double *lb_out, double *ub_out) {
    Py_ssize_t S = c->S, A = c->A, Z = c->Z;
    double bestQU = -INFINITY, bestQL = -INFINITY; Py_ssize_t aU = 0, aL = 0;
    i64 *kbest = malloc((size_t)Z * sizeof(i64)), *kL = malloc((size_t)Z * sizeof(i64));
    double *excess = malloc((size_t)Z * sizeof(double)), *exU = malloc((size_t)Z * sizeof(double));
    if (!kbest || !kL || !excess || !exU) { free(kbest); free(kL); free(excess); free(exU); PyErr_NoMemory(); return -1; }
    Py_ssize_t pe = belief_entry(c, b, nz, n);
    if (pe < 0) { free(kbest); free(kL); free(excess); free(exU); return -1; }
    i64 ver = c->uver[pe], now = (i64)c->plogn;
    for (Py_ssize_t a = 0; a < A; a++) {
        successors(c, b, nz, n, a);
        double r = 0.0;
        for (Py_ssize_t i = 0; i < n; i++) r += b[nz[i]] * c->R[nz[i] * A + a];
        double qu = r, ql = r;
        for (Py_ssize_t o = 0; o < Z; o++) {
            excess[o] = -INFINITY;
            if (c->sp[o] <= 0.0) { kbest[o] = -1; continue; }
            const double *sb = c->succ + o * S; const i64 *snz = c->snz + o * S;
            double lv, uv = with_upper ? cached_upper(c, pe, ver, a * Z + o, sb, snz, c->sn[o]) : 0.0;
            kbest[o] = best_alpha(c, sb, snz, c->sn[o], &lv);
            qu += c->g * c->sp[o] * uv;
            ql += c->g * c->sp[o] * lv;
            excess[o] = c->sp[o] * (uv - lv - thr);
        }
        clear_succ(c);
        if (qu > bestQU) { bestQU = qu; aU = a; memcpy(exU, excess, (size_t)Z * sizeof(double)); }
        if (ql > bestQL) { bestQL = ql; aL = a; memcpy(kL, kbest, (size_t)Z * sizeof(i64)); }
    }
    c->pact[pe] = aL;
    Py_ssize_t ob = 0;
    for (Py_ssize_t o = 1; o < Z; o++) if (exU[o] > exU[ob]) ob = o;
    *a_out = aU; *o_out = ob;
    double lb0; best_alpha(c, b, nz, n, &lb0);
    double ub0 = INFINITY;
    if (with_upper) {
        ub0 = cached_upper(c, pe, ver, A * Z, b, nz, n);
        c->uver[pe] = now;
    }
    int rc = 0;
    if (bestQL > lb0 + 1e-12 * (1.0 + fabs(lb0))) {
        /* the backed-up vector: alpha(s) = R(s,a) + g sum_s' T(s,a,s') sum_o O(a,s',o) alpha_k(o)(s') */
        for (Py_ssize_t t = 0; t < S; t++) {
            double acc = 0.0;
            const double *Oz = c->O + (aL * S + t) * Z;
            for (Py_ssize_t o = 0; o < Z; o++) {
                if (Oz[o] == 0.0) continue;
                i64 k = kL[o] >= 0 ? kL[o] : 0;
                acc += Oz[o] * c->al[t * c->Kcap + k];
            }
            c->w[t] = acc;
        }
        double *v = c->bt;  /* scratch of length S, all zero between calls */
        for (Py_ssize_t s = 0; s < S; s++) {
            i64 r = aL * S + s; double acc = 0.0;
            for (i64 k = c->tp[r]; k < c->tp[r + 1]; k++) acc += c->td[k] * c->w[c->ti[k]];
            v[s] = c->R[s * A + aL] + c->g * acc;
        }
        rc = add_alpha(c, v, aL);
        memset(v, 0, (size_t)S * sizeof(double));
        c->backups++;
        if (bestQL > lb0) lb0 = bestQL;
    }
    if (rc == 0 && with_upper && bestQU < ub0 - 1e-12 * (1.0 + fabs(ub0))) {
        rc = set_point(c, pe, bestQU);
        ub0 = bestQU;
    }
    free(kbest); free(kL); free(excess); free(exU);
    *lb_out = lb0; *ub_out = ub0;
    return rc;
}

/* An upper-bound backup at every visited belief, newest first (HSVI2 lowers UB along one path
 * per trial; this carries it to the beliefs the trials passed by, as the Python engine's
 * sweep_upper: web-ad 202 -> 77 trials here, 0.35 -> 0.16 s). */
static int sweep_upper(ctx_t *c) {
    Py_ssize_t S = c->S, A = c->A, Z = c->Z;
    double *b = c->db;
    i64 *sup = malloc((size_t)S * sizeof(i64));
    if (!sup) { PyErr_NoMemory(); return -1; }
    for (Py_ssize_t p = c->np_ - 1; p >= 0; p--) {
        if ((p & 63) == 0 && now_s() >= c->deadline) break;   /* (a partial sweep is still valid) */
        const i64 *ix = c->pidx + c->pstart[p]; const double *vx = c->pval + c->pstart[p];
        Py_ssize_t n = (Py_ssize_t)c->plen[p];
        for (Py_ssize_t j = 0; j < n; j++) { b[ix[j]] = vx[j]; sup[j] = ix[j]; }
        double best = -INFINITY;
        i64 ver = c->uver[p], now = (i64)c->plogn;
        for (Py_ssize_t a = 0; a < A; a++) {
            successors(c, b, sup, n, a);
            double q = 0.0;
            for (Py_ssize_t j = 0; j < n; j++) q += b[sup[j]] * c->R[sup[j] * A + a];
            for (Py_ssize_t o = 0; o < Z; o++)
                if (c->sp[o] > 0.0)
                    q += c->g * c->sp[o] * cached_upper(c, p, ver, a * Z + o, c->succ + o * S, c->snz + o * S, c->sn[o]);
            clear_succ(c);
            if (q > best) best = q;
        }
        c->uver[p] = now;
        for (Py_ssize_t j = 0; j < n; j++) b[ix[j]] = 0.0;
        if (set_point(c, p, best) < 0) { free(sup); return -1; }
        c->ub_sweep_backups++;
    }
    free(sup);
    c->ub_sweeps++;
    return 0;
}

/* n lower-bound backups at visited beliefs, round-robin from the newest (a deterministic
 * Perseus, Spaan & Vlassis 2005: the trials raise LB along their paths only; on models too big
 * to close the gap this spreads the vectors to the beliefs beside them, as the Python engine's
 * perseus_share). Returns the number of new vectors, or -1 on a memory error. */
static long sweep_lower(ctx_t *c, long n_backups, Py_ssize_t *cursor) {
    Py_ssize_t S = c->S;
    double *b = c->db;
    i64 *sup = malloc((size_t)S * sizeof(i64));
    if (!sup) { PyErr_NoMemory(); return -1; }
    long before = c->backups;
    for (long i = 0; i < n_backups && c->np_ > 0; i++) {
        if ((i & 63) == 63 && now_s() >= c->deadline) break;
        if (*cursor < 0 || *cursor >= c->np_) *cursor = c->np_ - 1;
        Py_ssize_t p = (*cursor)--;
        const i64 *ix = c->pidx + c->pstart[p]; const double *vx = c->pval + c->pstart[p];
        Py_ssize_t n = (Py_ssize_t)c->plen[p];
        for (Py_ssize_t j = 0; j < n; j++) { b[ix[j]] = vx[j]; sup[j] = ix[j]; }
        Py_ssize_t a, o; double l, u;
        int rc = backup(c, b, sup, n, 0.0, 0, &a, &o, &l, &u);
        for (Py_ssize_t j = 0; j < n; j++) b[sup[j]] = 0.0;
        if (rc < 0) { free(sup); return -1; }
        c->lb_sweep_backups++;
    }
    free(sup);
    return c->backups - before;
}

static int need(Py_buffer *b, Py_ssize_t item, Py_ssize_t n, const char *name) {
    if (b->len != n * item) {
        PyErr_Format(PyExc_ValueError, "_search_kernel.search: %s has %zd bytes, expected %zd (%zd items of %zd bytes)",
                     name, b->len, n * item, n, item);
        return -1;
    }
    return 0;
}

/* The fast informed bound (Hauskrecht 2000), in place (Gauss-Seidel) from the constant
 * Rmax/(1-g), which H maps below itself: the iterates decrease monotonically, so each is an upper
 * bound; stops when no entry moved by more than tol, after max_it sweeps or at the clock's
 * deadline (a looser start, not a wrong one). Q[s*A+a]. */
static Py_ssize_t fib(ctx_t *c, double *Q, double tol, Py_ssize_t max_it, double deadline) {
    Py_ssize_t S = c->S, A = c->A, Z = c->Z, it = 0;
    double rmax = -INFINITY;
    for (Py_ssize_t i = 0; i < S * A; i++) if (c->R[i] > rmax) rmax = c->R[i];
    for (Py_ssize_t i = 0; i < S * A; i++) Q[i] = rmax / (1.0 - c->g);
    double *acc = c->w;   /* Z*A scratch (w has max(S, Z*A) entries) */
    while (it < max_it) {
        it++;
        double moved = 0.0;
        for (Py_ssize_t s = 0; s < S; s++)
            for (Py_ssize_t a = 0; a < A; a++) {
                for (Py_ssize_t i = 0; i < Z * A; i++) acc[i] = 0.0;
                i64 r = a * S + s;
                for (i64 k = c->tp[r]; k < c->tp[r + 1]; k++) {
                    i64 t = c->ti[k];
                    const double *Oz = c->O + (a * S + t) * Z, *Qt = Q + t * A;
                    for (Py_ssize_t o = 0; o < Z; o++) {
                        double wgt = c->td[k] * Oz[o];
                        if (wgt == 0.0) continue;
                        for (Py_ssize_t a2 = 0; a2 < A; a2++) acc[o * A + a2] += wgt * Qt[a2];
                    }
                }
                double v = 0.0;
                for (Py_ssize_t o = 0; o < Z; o++) {
                    double m = acc[o * A];
                    for (Py_ssize_t a2 = 1; a2 < A; a2++) if (acc[o * A + a2] > m) m = acc[o * A + a2];
                    v += m;
                }
                v = c->R[s * A + a] + c->g * v;
                double old = Q[s * A + a];
                if (v < old) {       /* monotone: never raise an upper bound (rounding) */
                    if (old - v > moved) moved = old - v;
                    Q[s * A + a] = v;
                }
            }
        if (moved <= tol || now_s() >= deadline) break;
    }
    return it;
}

/* The blind policies "always do a" (Hauskrecht 2000), each from the constant min_s R(s,a)/(1-g)
 * below its value, in place: the iterates rise monotonically and stay below the policy's value,
 * so each is a valid lower bound (also when the deadline stops them). al[a*S+s]. */
static Py_ssize_t blind(ctx_t *c, double *al, double tol, Py_ssize_t max_it, double deadline) {
    Py_ssize_t S = c->S, A = c->A, it_max = 0;
    for (Py_ssize_t a = 0; a < A; a++) {
        double rmin = INFINITY, *v = al + a * S;
        for (Py_ssize_t s = 0; s < S; s++) if (c->R[s * A + a] < rmin) rmin = c->R[s * A + a];
        for (Py_ssize_t s = 0; s < S; s++) v[s] = rmin / (1.0 - c->g);
        Py_ssize_t it = 0;
        while (it < max_it) {
            it++;
            double moved = 0.0;
            for (Py_ssize_t s = 0; s < S; s++) {
                i64 r = a * S + s; double acc = 0.0;
                for (i64 k = c->tp[r]; k < c->tp[r + 1]; k++) acc += c->td[k] * v[c->ti[k]];
                double nv = c->R[s * A + a] + c->g * acc;
                if (nv > v[s]) { if (nv - v[s] > moved) moved = nv - v[s]; v[s] = nv; }
            }
            if (moved <= tol || now_s() >= deadline) break;
        }
        if (it > it_max) it_max = it;
    }
    return it_max;
}

static PyObject *search(PyObject *Py_UNUSED(self), PyObject *args) {
    Py_ssize_t S, A, Z, init_max_it; double g, eps, kappa, limit, init_tol, ub_sweep_ratio, lb_share;
    long long max_trials; Py_ssize_t backoff;
    Py_buffer R, O, b0, tp, ti, td;
    if (!PyArg_ParseTuple(args, "nnndy*y*y*y*y*y*ddddnLddn", &S, &A, &Z, &g, &R, &O, &tp, &ti, &td, &b0,
                          &eps, &kappa, &init_tol, &limit, &init_max_it, &max_trials, &ub_sweep_ratio,
                          &lb_share, &backoff))
        return NULL;
    Py_buffer *bufs[] = {&R, &O, &b0, &tp, &ti, &td};
    PyObject *out = NULL;
    ctx_t c; memset(&c, 0, sizeof c);
    double *path = NULL, *Q = NULL, *al0 = NULL; i64 *pnz = NULL, *nz0 = NULL; Py_ssize_t *pn = NULL;
    if (S < 1 || A < 1 || Z < 1) {
        PyErr_Format(PyExc_ValueError, "_search_kernel.search: S, A and Z must be >= 1 (got S=%zd A=%zd Z=%zd)",
                     S, A, Z);
        goto done;
    }
    if (!(g > 0.0 && g < 1.0) || !(eps > 0.0) || !(kappa > 0.0 && kappa <= 1.0) || !(limit > 0.0) ||
        !(init_tol > 0.0) || init_max_it < 1 || !(ub_sweep_ratio >= 0.0) || !(lb_share >= 0.0) || backoff < 0) {
        PyErr_Format(PyExc_ValueError, "_search_kernel.search: need 0 < discount < 1 (got %g), epsilon > 0 (got %g), "
                     "0 < kappa <= 1 (got %g), time limit > 0 (got %g), init tolerance > 0 (got %g) and "
                     "init iterations >= 1 (got %zd), ub_sweep_ratio >= 0 (got %g), lb_share >= 0 (got %g) "
                     "and backoff >= 0 (got %zd)", g, eps, kappa, limit, init_tol, init_max_it, ub_sweep_ratio,
                     lb_share, backoff);
        goto done;
    }
    if (need(&R, 8, S * A, "R") || need(&O, 8, A * S * Z, "O") || need(&b0, 8, S, "b0") ||
        need(&tp, 8, A * S + 1, "T row pointers"))
        goto done;
    c.S = S; c.A = A; c.Z = Z; c.g = g;
    c.R = R.buf; c.O = O.buf; c.b0 = b0.buf; c.tp = tp.buf; c.ti = ti.buf; c.td = td.buf;
    Py_ssize_t nnz = ti.len / 8;
    if (td.len != ti.len || c.tp[0] != 0 || c.tp[A * S] != nnz) {
        PyErr_SetString(PyExc_ValueError, "_search_kernel.search: T's CSR arrays disagree (values and column "
                        "indices differ in length, or the row pointers do not run from 0 to their count)");
        goto done;
    }
    for (Py_ssize_t r = 0; r < A * S; r++)
        if (c.tp[r + 1] < c.tp[r]) {
            PyErr_Format(PyExc_ValueError, "_search_kernel.search: T's row pointers decrease at row %zd", r);
            goto done;
        }
    for (Py_ssize_t k = 0; k < nnz; k++)
        if (c.ti[k] < 0 || c.ti[k] >= S || !(c.td[k] >= 0.0)) {
            PyErr_Format(PyExc_ValueError, "_search_kernel.search: T entry %zd: state %lld outside 0..%zd or "
                         "probability %g negative", k, (long long)c.ti[k], S - 1, c.td[k]);
            goto done;
        }
    double bsum = 0.0;
    for (Py_ssize_t s = 0; s < S; s++) {
        if (!(c.b0[s] >= 0.0)) {
            PyErr_Format(PyExc_ValueError, "_search_kernel.search: b0[%zd] = %g is not a probability", s, c.b0[s]);
            goto done;
        }
        bsum += c.b0[s];
    }
    if (fabs(bsum - 1.0) > 1e-6) {
        PyErr_Format(PyExc_ValueError, "_search_kernel.search: b0 sums to %.9g, not 1", bsum);
        goto done;
    }
    Py_ssize_t wn = S > Z * A ? S : Z * A;
    c.Vc = malloc((size_t)S * sizeof(double));
    c.bt = calloc((size_t)S, sizeof(double));
    c.btnz = malloc((size_t)(S + 1) * sizeof(i64));
    c.mark = calloc((size_t)S, 1);
    c.succ = calloc((size_t)(Z * S), sizeof(double));
    c.snz = malloc((size_t)(Z * S) * sizeof(i64));
    c.sn = malloc((size_t)Z * sizeof(Py_ssize_t));
    c.sp = malloc((size_t)Z * sizeof(double));
    c.w = malloc((size_t)wn * sizeof(double));
    c.db = calloc((size_t)S, sizeof(double));
    Q = malloc((size_t)(S * A) * sizeof(double));
    al0 = malloc((size_t)(S * A) * sizeof(double));
    nz0 = malloc((size_t)S * sizeof(i64));
    if (!c.Vc || !c.bt || !c.btnz || !c.mark || !c.succ || !c.snz || !c.sn || !c.sp || !c.w || !c.db || !Q || !al0 || !nz0) {
        PyErr_NoMemory();
        goto done;
    }
    double t0 = now_s();
    c.deadline = t0 + limit;
    /* Bounds to start from: FIB above (with the corner values of the sawtooth), blind policies below. */
    /* The start bounds get a tenth of the time limit (at least 0.5 s), as the Python engine's FIB. */
    double init_deadline = t0 + (limit < 5.0 ? (limit < 0.5 ? limit : 0.5) : 0.1 * limit);
    Py_ssize_t fib_it = fib(&c, Q, init_tol, init_max_it, init_deadline);
    c.Q = Q;
    for (Py_ssize_t s = 0; s < S; s++) {
        double m = -INFINITY;
        for (Py_ssize_t a = 0; a < A; a++) if (Q[s * A + a] > m) m = Q[s * A + a];
        c.Vc[s] = m;
    }
    Py_ssize_t blind_it = blind(&c, al0, init_tol, init_max_it, init_deadline + 0.5 * (init_deadline - t0));
    for (Py_ssize_t a = 0; a < A; a++)
        if (add_alpha(&c, al0 + a * S, a) < 0) goto done;
    c.K_pruned = c.K;
    double init_s = now_s() - t0;
    double rmin = INFINITY, rmax = -INFINITY;
    for (Py_ssize_t i = 0; i < S * A; i++) {
        if (c.R[i] < rmin) rmin = c.R[i];
        if (c.R[i] > rmax) rmax = c.R[i];
    }
    double span = (rmax - rmin) / (1.0 - g);   /* no width exceeds this */

    Py_ssize_t dcap = 0;
    long long trials = 0, trial_backups = 0, at_ub_sweep = 0;
    Py_ssize_t lb_cursor = -1, lb_skip = 0, lb_wait = 0;
    const char *stop = "time";
    Py_ssize_t n0 = 0;
    for (Py_ssize_t s = 0; s < S; s++) if (c.b0[s] > 0.0) nz0[n0++] = s;
    double lb, ub;
    best_alpha(&c, c.b0, nz0, n0, &lb);
    ub = upper(&c, c.b0, nz0, n0);
    for (;;) {
        if (ub - lb <= eps) { stop = "epsilon"; break; }
        if (max_trials > 0 && trials >= max_trials) { stop = "trials"; break; }
        if (now_s() - t0 >= limit) { stop = "time"; break; }
        /* The trial's target width at b0: a share kappa of the gap while it is wide (shallow
         * trials that refine the bounds near b0), half the target near the end (so that one
         * more trial can close it), as the Python engine's trials. */
        double gap0 = ub - lb, eps_t = 0.5 * eps;
        if (gap0 > 10.0 * eps) eps_t = kappa * gap0 > eps ? kappa * gap0 : eps;
        /* Below this depth even the widest gap is within eps_t g^-d (a guard: the width test stops first). */
        Py_ssize_t max_d = span > eps_t ? (Py_ssize_t)ceil(log(eps_t / span) / log(g)) + 1 : 1;
        /* forward */
        Py_ssize_t d = 0;
        for (;;) {
            if (d + 1 > dcap) {
                Py_ssize_t nc = dcap ? 2 * dcap : 64;
                double *p2 = realloc(path, (size_t)nc * (size_t)S * sizeof(double));
                if (p2) path = p2;
                i64 *np2 = p2 ? realloc(pnz, (size_t)nc * (size_t)S * sizeof(i64)) : NULL;
                if (np2) pnz = np2;
                Py_ssize_t *pn2 = np2 ? realloc(pn, (size_t)nc * sizeof(Py_ssize_t)) : NULL;
                if (!pn2) { PyErr_NoMemory(); goto done; }
                pn = pn2; dcap = nc;
            }
            double *b = path + d * S; i64 *nz = pnz + d * S;
            if (d == 0) {
                memcpy(b, c.b0, (size_t)S * sizeof(double));
                memcpy(nz, nz0, (size_t)n0 * sizeof(i64)); pn[0] = n0;
            }
            double scale = pow(g, -(double)d);
            Py_ssize_t a, o; double l, u;
            if (backup(&c, b, nz, pn[d], eps_t * scale / g, 1, &a, &o, &l, &u) < 0) goto done;
            if (u - l <= eps_t * scale || d + 1 >= max_d) break;
            /* step to the successor b^{a,o} */
            successors(&c, b, nz, pn[d], a);
            if (c.sp[o] <= 0.0) { clear_succ(&c); break; }
            if (d + 2 > dcap) {
                Py_ssize_t nc = 2 * dcap;
                double *p2 = realloc(path, (size_t)nc * (size_t)S * sizeof(double));
                if (p2) path = p2;
                i64 *np2 = p2 ? realloc(pnz, (size_t)nc * (size_t)S * sizeof(i64)) : NULL;
                if (np2) pnz = np2;
                Py_ssize_t *pn2 = np2 ? realloc(pn, (size_t)nc * sizeof(Py_ssize_t)) : NULL;
                if (!pn2) { clear_succ(&c); PyErr_NoMemory(); goto done; }
                pn = pn2; dcap = nc;
                b = path + d * S;
            }
            double *nb = path + (d + 1) * S; i64 *nnz2 = pnz + (d + 1) * S;
            memset(nb, 0, (size_t)S * sizeof(double));
            pn[d + 1] = c.sn[o];
            for (Py_ssize_t i = 0; i < c.sn[o]; i++) {
                i64 t = c.snz[o * S + i];
                nnz2[i] = t; nb[t] = c.succ[o * S + t];
            }
            clear_succ(&c);
            d++;
        }
        /* backward: both bounds backed up at every belief of the path, deepest first */
        for (Py_ssize_t k = d; k >= 0; k--) {
            Py_ssize_t a, o; double l, u;
            if (backup(&c, path + k * S, pnz + k * S, pn[k], 0.0, 1, &a, &o, &l, &u) < 0) goto done;
            trial_backups++;
        }
        if (ub_sweep_ratio > 0.0 && (double)(trial_backups - at_ub_sweep) >= ub_sweep_ratio * (double)c.np_) {
            if (sweep_upper(&c) < 0) goto done;
            at_ub_sweep = trial_backups;
        }
        if (lb_share > 0.0) {
            /* lb_share LB backups per trial backup at the visited beliefs; a round that adds no
             * vector makes the next rounds wait 1, 2, 4, ... trials (at most backoff), one that
             * does resets the wait (the Python engine's spread_backoff). */
            if (lb_wait > 0) lb_wait--;
            else {
                long gained = sweep_lower(&c, (long)ceil(lb_share * (double)(d + 1)), &lb_cursor);
                if (gained < 0) goto done;
                if (gained > 0 || backoff == 0) lb_skip = 0;
                else {
                    lb_skip = lb_skip ? 2 * lb_skip : 1;
                    if (lb_skip > backoff) lb_skip = backoff;
                }
                lb_wait = lb_skip;
            }
        }
        if (c.K > 2 * c.K_pruned + 50 && prune_alphas(&c) < 0) goto done;
        best_alpha(&c, c.b0, nz0, n0, &lb);
        double u0 = upper(&c, c.b0, nz0, n0);
        if (u0 < ub) ub = u0;
        trials++;
    }
    {
        /* (vector-major, K x S, for the caller) */
        PyObject *alb = PyBytes_FromStringAndSize(NULL, (Py_ssize_t)(c.K * S * (Py_ssize_t)sizeof(double)));
        if (alb) {
            double *dst = (double *)PyBytes_AS_STRING(alb);
            for (Py_ssize_t s = 0; s < S; s++)
                for (Py_ssize_t k = 0; k < c.K; k++) dst[k * S + s] = c.al[s * c.Kcap + k];
        }
        PyObject *acb = PyBytes_FromStringAndSize((const char *)c.act, (Py_ssize_t)(c.K * (Py_ssize_t)sizeof(i64)));
        if (alb && acb)
            out = Py_BuildValue("{s:N,s:N,s:n,s:d,s:d,s:L,s:l,s:n,s:s,s:d,s:d,s:n,s:n,s:L,s:l,s:l,s:l,s:l}", "alphas", alb, "actions", acb,
                                "vectors", c.K, "lower", lb, "upper", ub, "trials", trials, "backups", c.backups,
                                "ub_points", c.np_, "stop", stop, "seconds", now_s() - t0, "init_seconds", init_s,
                                "fib_iterations", fib_it, "blind_iterations", blind_it, "trial_backups", trial_backups,
                                "ub_sweeps", c.ub_sweeps, "ub_sweep_backups", c.ub_sweep_backups,
                                "lb_sweep_backups", c.lb_sweep_backups, "corner_updates", c.corner_updates);
        else { Py_XDECREF(alb); Py_XDECREF(acb); }
    }
done:
    for (size_t i = 0; i < sizeof bufs / sizeof bufs[0]; i++) PyBuffer_Release(bufs[i]);
    free(c.Vc); free(c.al); free(c.kacc); free(c.act); free(c.pidx); free(c.pval); free(c.pstart); free(c.plen); free(c.pdelta); free(c.pv);
    free(c.phash); free(c.htab); free(c.keep); free(c.db); free(c.ucache); free(c.uver); free(c.pact); free(c.plog);
    free(c.sidx); free(c.sinv);
    free(c.bt); free(c.btnz); free(c.mark); free(c.succ); free(c.snz); free(c.sn); free(c.sp); free(c.w);
    free(path); free(pnz); free(pn); free(Q); free(al0); free(nz0);
    return out;
}

static PyMethodDef methods[] = {
    {"search", search, METH_VARARGS,
     "search(S, A, Z, discount, R, O, t_ptr, t_ind, t_dat, b0, epsilon, kappa, init_tol, time_limit,\n"
     "       init_max_iterations, max_trials, ub_sweep_ratio, lb_share, backoff) -> dict: the whole HSVI2 search (see point_based.py)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_search_kernel",
                                    "The point-based solver's search loop in C (engine='c').", -1, methods,
                                    NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__search_kernel(void) { return PyModule_Create(&module); }

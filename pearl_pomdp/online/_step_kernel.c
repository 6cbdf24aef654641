/* ExplicitModel.step in C: one step of N particles of an explicit POMDP (pearl_pomdp/online/generative.py).
 *
 * Why C: DESPOT steps a node's particles once per action and expansion. On the ward (233,280
 * states, 15 actions) the numpy version cost ~0.25 ms a call, ~80 % of a decision, nearly all of it
 * numpy's fixed cost per call and the temporaries of a few hundred particles. This is the only
 * implementation of the step (no Python twin in the package; the tests hold a numpy reference of
 * the definition below and compare bit for bit).
 *
 * The definition (one for both draws; "the row" is T[a][s, :] as its CSR entries in stored order,
 * or O[a, s', :]):
 *   c_k = p_1 + ... + p_k, summed left to right in double (float32 entries are widened first);
 *   M = c_n (the row's mass, the same sum); the target t = u * M;
 *   the draw is the first k with c_k > t; when there is none (t rounded up to M), the last k with
 *   p_k > 0 takes the rounding residue. An entry with p_k = 0 is never drawn. (Because M is the
 *   same running sum, u < 1 gives t < M = c_n for any normal M: the residue clause is reached only
 *   by a subnormal mass. The numpy code before this kernel compared against one cumulative sum
 *   across all particles' rows, where rounding could move a draw across a step; here each row is
 *   summed on its own.)
 * s' is drawn from T[a][s, :] with u = uniforms[i, 0], o from O[a, s', :] with u = uniforms[i, 1],
 * and the reward is R[s, a]. A row whose mass is not a positive finite number is an error.
 *
 * T's rows come with tables made once per model (row_tables): each row's mass ([S] float64 per
 * action, 28 MB on the ward) and, at every BLOCK-th position j of data (a global grid), the running
 * sum of j's row before j ("ends") and the largest running sum of that row over j..j+BLOCK-1
 * ("peaks"): 2 * nnz / BLOCK doubles, 10 MB on the ward. A draw adds up the entries before the
 * row's first grid point, then skips each block whose peak is <= t (no c_k > t in it) and scans
 * the first one whose peak is > t from its end value: the same c_k, the same comparisons, the same
 * k as the plain scan, in ~n / BLOCK + 2 * BLOCK steps instead of ~n / 2. The ward's rows at its
 * beliefs hold ~380 entries; summing each twice was ~3/4 of the step, scanning once ~2/3 of the
 * rest. O's rows (Z entries) are summed here.
 *
 * Arrays come through the buffer protocol (no numpy headers), C-contiguous, never copied: the
 * CSR index arrays as int32 or int64, T's data and O as float32 or float64 (the ward's O is
 * 210 MB of float32). Their formats and shapes are checked, and so is every index this call reads
 * (the particles' states, their rows' bounds in indptr, each drawn column): bad input is a
 * ValueError naming the argument, never a read out of bounds. The GIL is released for the loop.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* The element kinds this kernel reads. */
enum { K_I32, K_I64, K_F32, K_F64 };

static const char *kind_name[] = {"int32", "int64", "float32", "float64"};

/* The kind of a buffer's format ("i", "l", "q", "f", "d", with an optional native byte-order
 * prefix), or -1. */
static int buffer_kind(const Py_buffer *b) {
    const char *f = b->format ? b->format : "B";
    if (*f == '@' || *f == '=') f++;
#if PY_LITTLE_ENDIAN
    else if (*f == '<') f++;
#else
    else if (*f == '>' || *f == '!') f++;
#endif
    if (f[0] == '\0' || f[1] != '\0') return -1;
    switch (f[0]) {
    case 'i': case 'l': case 'q':
        if (b->itemsize == 4) return K_I32;
        if (b->itemsize == 8) return K_I64;
        return -1;
    case 'f': return b->itemsize == 4 ? K_F32 : -1;
    case 'd': return b->itemsize == 8 ? K_F64 : -1;
    default: return -1;
    }
}

/* Takes obj's buffer as a C-contiguous array of ndim dimensions whose kind is one of the
 * allowed (a bit mask of 1 << kind); 0 on success, -1 with a ValueError naming `name`. */
static int take(const char *fn, PyObject *obj, Py_buffer *b, int writable, int ndim, unsigned allowed,
                const char *name) {
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, b, flags) < 0) {
        PyErr_Clear();
        PyErr_Format(PyExc_ValueError, "_step_kernel.%s: %s must be a C-contiguous%s array (got %.80s)", fn, name,
                     writable ? ", writable" : "", Py_TYPE(obj)->tp_name);
        b->obj = NULL;
        return -1;
    }
    int kind = buffer_kind(b);
    if (kind < 0 || !(allowed & (1u << kind))) {
        char want[64] = "";
        for (int k = K_I32; k <= K_F64; k++)
            if (allowed & (1u << k)) {
                if (want[0]) strcat(want, " or ");
                strcat(want, kind_name[k]);
            }
        PyErr_Format(PyExc_ValueError, "_step_kernel.%s: %s must hold %s, got format '%s' (%zd-byte items)", fn, name,
                     want, b->format ? b->format : "B", b->itemsize);
        PyBuffer_Release(b);
        b->obj = NULL;
        return -1;
    }
    if (b->ndim != ndim) {
        PyErr_Format(PyExc_ValueError, "_step_kernel.%s: %s must be %d-D, got %d-D", fn, name, ndim, b->ndim);
        PyBuffer_Release(b);
        b->obj = NULL;
        return -1;
    }
    return kind;
}

/* Releases the buffers of `all` that take() filled (the others have obj NULL). */
static void release_all(Py_buffer **all, size_t n) {
    for (size_t j = 0; j < n; j++)
        if (all[j]->obj != NULL) PyBuffer_Release(all[j]);
}

static inline int64_t ix_at(const void *p, int kind, Py_ssize_t k) {
    return kind == K_I64 ? ((const int64_t *)p)[k] : (int64_t)((const int32_t *)p)[k];
}

static inline double val_at(const void *p, int kind, Py_ssize_t k) {
    return kind == K_F64 ? ((const double *)p)[k] : (double)((const float *)p)[k];
}

/* The row's mass: its n entries at p summed left to right in double. */
static inline double row_sum(const void *p, int kind, Py_ssize_t n) {
    double m = 0.0;
    for (Py_ssize_t k = 0; k < n; k++) m += val_at(p, kind, k);
    return m;
}

/* The draw of the definition above from the n entries at p, whose row_sum is m (a positive
 * finite number): their position. */
static inline Py_ssize_t draw_in(const void *p, int kind, Py_ssize_t n, double u, double m) {
    double t = u * m, c = 0.0;
    for (Py_ssize_t k = 0; k < n; k++) {
        c += val_at(p, kind, k);
        if (c > t) return k;
    }
    for (Py_ssize_t k = n - 1; k >= 0; k--)
        if (val_at(p, kind, k) > 0.0) return k;
    return n - 1;   /* (not reached: M > 0 needs a positive entry) */
}

static inline int usable_mass(double m) { return m > 0.0 && isfinite(m); }

/* The grid of row_tables' blocks (positions of data). */
#define BLOCK 32

/* How many particles ahead step asks for the rows it will read (a hint: no effect on results). */
#define PREFETCH 8
#if defined(__GNUC__) || defined(__clang__)
#define PREFETCH_AT(p) __builtin_prefetch((p), 0, 1)
#else
#define PREFETCH_AT(p) ((void)(p))
#endif

/* The draw of the definition in T's row [lo, hi) of data (positions of the whole array at td),
 * mass m (a positive finite number), with row_tables' ends and peaks: the position in the row. */
static inline Py_ssize_t draw_row(const void *td, int kind, int64_t lo, int64_t hi, double u, double m,
                                  const double *ends, const double *peaks) {
    double t = u * m, c = 0.0;
    int64_t grid = (lo + BLOCK - 1) / BLOCK * BLOCK, stop = grid < hi ? grid : hi;
    for (int64_t k = lo; k < stop; k++) {
        c += val_at(td, kind, (Py_ssize_t)k);
        if (c > t) return (Py_ssize_t)(k - lo);
    }
    for (int64_t j = grid; j < hi; j += BLOCK) {
        if (!(peaks[j / BLOCK] > t)) continue;          /* no running sum in this block exceeds t */
        int64_t end = j + BLOCK < hi ? j + BLOCK : hi;
        c = ends[j / BLOCK];                            /* the running sum before j, as the scan has it */
        for (int64_t k = j; k < end; k++) {
            c += val_at(td, kind, (Py_ssize_t)k);
            if (c > t) return (Py_ssize_t)(k - lo);
        }
    }
    for (int64_t k = hi - 1; k >= lo; k--)
        if (val_at(td, kind, (Py_ssize_t)k) > 0.0) return (Py_ssize_t)(k - lo);
    return (Py_ssize_t)(hi - lo - 1);   /* (not reached: M > 0 needs a positive entry) */
}

/* What went wrong inside the loop (raised after the GIL is back). */
enum { E_NONE, E_STATE, E_UNIFORM, E_INDPTR, E_COLUMN, E_T_MASS, E_O_MASS };

typedef struct {
    int code;
    Py_ssize_t i;        /* the particle */
    int64_t s, v, w;     /* its state; the offending value(s) */
    double x;
} fault_t;

/* A ValueError whose format ends with %s for x (PyErr_Format has no float conversion). The
 * three integer arguments come first in the format: a Py_ssize_t and two long longs. */
static void raise_with_number(const char *format, double x, Py_ssize_t i, long long v, long long w) {
    char *text = PyOS_double_to_string(x, 'r', 0, Py_DTSF_ADD_DOT_0, NULL);
    if (text == NULL) return;
    PyErr_Format(PyExc_ValueError, format, i, v, w, text);
    PyMem_Free(text);
}

static PyObject *step(PyObject *Py_UNUSED(self), PyObject *args) {
    PyObject *o_ptr, *o_ind, *o_dat, *o_ms, *o_en, *o_pk, *o_O, *o_R, *o_st, *o_u, *o_nx, *o_ob, *o_rw;
    Py_ssize_t a;
    if (!PyArg_ParseTuple(args, "OOOOOOOOnOOOOO:step", &o_ptr, &o_ind, &o_dat, &o_ms, &o_en, &o_pk, &o_O, &o_R, &a,
                          &o_st, &o_u, &o_nx, &o_ob, &o_rw))
        return NULL;
    Py_buffer ptr = {0}, ind = {0}, dat = {0}, ms = {0}, en = {0}, pk = {0}, O = {0}, R = {0}, st = {0}, uu = {0},
              nx = {0}, ob = {0}, rw = {0};
    Py_buffer *all[] = {&ptr, &ind, &dat, &ms, &en, &pk, &O, &R, &st, &uu, &nx, &ob, &rw};
    PyObject *ret = NULL;
    const unsigned INTS = (1u << K_I32) | (1u << K_I64), FLOATS = (1u << K_F32) | (1u << K_F64);
    int kp, ki, kd, ko;
    const unsigned F64 = 1u << K_F64, I64 = 1u << K_I64;
    if ((kp = take("step", o_ptr, &ptr, 0, 1, INTS, "indptr")) < 0
        || (ki = take("step", o_ind, &ind, 0, 1, INTS, "indices")) < 0
        || (kd = take("step", o_dat, &dat, 0, 1, FLOATS, "data")) < 0 || take("step", o_ms, &ms, 0, 1, F64, "mass") < 0
        || take("step", o_en, &en, 0, 1, F64, "ends") < 0 || take("step", o_pk, &pk, 0, 1, F64, "peaks") < 0
        || (ko = take("step", o_O, &O, 0, 3, FLOATS, "O")) < 0 || take("step", o_R, &R, 0, 2, F64, "R") < 0
        || take("step", o_st, &st, 0, 1, I64, "states") < 0 || take("step", o_u, &uu, 0, 2, F64, "uniforms") < 0
        || take("step", o_nx, &nx, 1, 1, I64, "next_out") < 0 || take("step", o_ob, &ob, 1, 1, I64, "obs_out") < 0
        || take("step", o_rw, &rw, 1, 1, F64, "reward_out") < 0)
        goto done;
    Py_ssize_t A = O.shape[0], S = O.shape[1], Z = O.shape[2], N = st.shape[0], nnz = ind.shape[0];
    if (S < 1 || Z < 1 || A < 1) {
        PyErr_Format(PyExc_ValueError, "_step_kernel.step: O has shape (%zd, %zd, %zd): expected [A, S, Z], none empty",
                     A, S, Z);
        goto done;
    }
    if (a < 0 || a >= A) {
        PyErr_Format(PyExc_ValueError, "_step_kernel.step: action %zd is not in 0..%zd (O has %zd actions)", a, A - 1, A);
        goto done;
    }
    if (ptr.shape[0] != S + 1) {
        PyErr_Format(PyExc_ValueError, "_step_kernel.step: indptr has %zd entries, expected S + 1 = %zd (O's S = %zd)",
                     ptr.shape[0], S + 1, S);
        goto done;
    }
    if (dat.shape[0] != nnz) {
        PyErr_Format(PyExc_ValueError, "_step_kernel.step: data has %zd entries, indices %zd: expected the same", dat.shape[0],
                     nnz);
        goto done;
    }
    if (ms.shape[0] != S) {
        PyErr_Format(PyExc_ValueError, "_step_kernel.step: mass has %zd entries, expected S = %zd (O's S)", ms.shape[0], S);
        goto done;
    }
    if (en.shape[0] != nnz / BLOCK + 1 || pk.shape[0] != nnz / BLOCK + 1) {
        PyErr_Format(PyExc_ValueError, "_step_kernel.step: ends and peaks have %zd and %zd entries, expected "
                     "len(data) // BLOCK + 1 = %zd (BLOCK = %d)", en.shape[0], pk.shape[0], nnz / BLOCK + 1, BLOCK);
        goto done;
    }
    if (R.shape[0] != S || R.shape[1] != A) {
        PyErr_Format(PyExc_ValueError, "_step_kernel.step: R has shape (%zd, %zd), expected [S, A] = (%zd, %zd)", R.shape[0],
                     R.shape[1], S, A);
        goto done;
    }
    if (uu.shape[0] != N || uu.shape[1] < 2) {
        PyErr_Format(PyExc_ValueError, "_step_kernel.step: uniforms has shape (%zd, %zd), expected [N, >= 2] with N = %zd "
                     "(the states)", uu.shape[0], uu.shape[1], N);
        goto done;
    }
    if (nx.shape[0] != N || ob.shape[0] != N || rw.shape[0] != N) {
        PyErr_Format(PyExc_ValueError, "_step_kernel.step: next_out, obs_out, reward_out have %zd, %zd, %zd entries, "
                     "expected N = %zd (the states)", nx.shape[0], ob.shape[0], rw.shape[0], N);
        goto done;
    }
    {
        const void *tp = ptr.buf, *ti = ind.buf, *td = dat.buf;
        const char *Ob = (const char *)O.buf;
        const double *Rb = (const double *)R.buf, *ub = (const double *)uu.buf, *mb = (const double *)ms.buf;
        const double *eb = (const double *)en.buf, *pb = (const double *)pk.buf;
        const int64_t *sb = (const int64_t *)st.buf;
        int64_t *nxt = (int64_t *)nx.buf, *obs = (int64_t *)ob.buf;
        double *rew = (double *)rw.buf;
        Py_ssize_t U = uu.shape[1], osize = O.itemsize;
        fault_t f = {E_NONE, 0, 0, 0, 0, 0.0};
        Py_BEGIN_ALLOW_THREADS
        /* Two passes, s' for every particle, then o: the particles' rows are scattered over hundreds of
         * MB, so each pass asks for the rows of the particles PREFETCH ahead before it reads its own
         * (the outcomes are those of one pass: only the order of the reads changes). */
        for (Py_ssize_t i = 0; i < N; i++) {
            if (i + 2 * PREFETCH < N) {
                int64_t sp = sb[i + 2 * PREFETCH];
                if (sp >= 0 && sp < S) {
                    PREFETCH_AT(kp == K_I64 ? (const void *)((const int64_t *)tp + sp) : (const void *)((const int32_t *)tp + sp));
                    PREFETCH_AT(mb + sp);
                }
            }
            if (i + PREFETCH < N) {
                int64_t sp = sb[i + PREFETCH];
                if (sp >= 0 && sp < S) {
                    int64_t lp = ix_at(tp, kp, sp), hp = ix_at(tp, kp, sp + 1);
                    if (lp >= 0 && lp < hp && hp <= nnz) {
                        PREFETCH_AT(kd == K_F64 ? (const void *)((const double *)td + lp) : (const void *)((const float *)td + lp));
                        PREFETCH_AT(pb + lp / BLOCK);
                    }
                }
            }
            int64_t s = sb[i];
            double u0 = ub[i * U], u1 = ub[i * U + 1], mass;
            if (s < 0 || s >= S) { f = (fault_t){E_STATE, i, s, 0, 0, 0.0}; break; }
            if (!(u0 >= 0.0 && u0 < 1.0)) { f = (fault_t){E_UNIFORM, i, s, 0, 0, u0}; break; }
            if (!(u1 >= 0.0 && u1 < 1.0)) { f = (fault_t){E_UNIFORM, i, s, 1, 0, u1}; break; }
            int64_t lo = ix_at(tp, kp, s), hi = ix_at(tp, kp, s + 1);
            if (lo < 0 || hi < lo || hi > nnz) { f = (fault_t){E_INDPTR, i, s, lo, hi, 0.0}; break; }
            mass = mb[s];
            if (!usable_mass(mass)) { f = (fault_t){E_T_MASS, i, s, hi - lo, 0, mass}; break; }
            Py_ssize_t k = draw_row(td, kd, lo, hi, u0, mass, eb, pb);
            int64_t s2 = ix_at(ti, ki, (Py_ssize_t)lo + k);
            if (s2 < 0 || s2 >= S) { f = (fault_t){E_COLUMN, i, s, s2, lo + k, 0.0}; break; }
            nxt[i] = s2;
            rew[i] = Rb[s * A + a];
        }
        for (Py_ssize_t i = 0; f.code == E_NONE && i < N; i++) {
            if (i + PREFETCH < N)
                PREFETCH_AT(Ob + ((size_t)a * (size_t)S + (size_t)nxt[i + PREFETCH]) * (size_t)Z * (size_t)osize);
            int64_t s2 = nxt[i];
            const void *orow = Ob + ((size_t)a * (size_t)S + (size_t)s2) * (size_t)Z * (size_t)osize;
            double mass = row_sum(orow, ko, Z);
            if (!usable_mass(mass)) { f = (fault_t){E_O_MASS, i, sb[i], s2, 0, mass}; break; }
            obs[i] = draw_in(orow, ko, Z, ub[i * U + 1], mass);
        }
        Py_END_ALLOW_THREADS
        switch (f.code) {
        case E_NONE:
            ret = Py_None;
            Py_INCREF(ret);
            break;
        case E_STATE:
            PyErr_Format(PyExc_ValueError, "_step_kernel.step: states[%zd] = %lld is not a state (0..%zd)", f.i,
                         (long long)f.s, S - 1);
            break;
        case E_UNIFORM:
            raise_with_number("_step_kernel.step: uniforms[%zd, %lld] (particle in state %lld) = %s is not in [0, 1)", f.x,
                              f.i, (long long)f.v, (long long)f.s);
            break;
        case E_INDPTR:
            PyErr_Format(PyExc_ValueError, "_step_kernel.step: the row of state %lld, indptr[%lld:%lld + 2] = [%lld, %lld], "
                         "is not a range within the %zd indices", (long long)f.s, (long long)f.s, (long long)f.s,
                         (long long)f.v, (long long)f.w, nnz);
            break;
        case E_COLUMN:
            PyErr_Format(PyExc_ValueError, "_step_kernel.step: indices[%lld] = %lld (row %lld) is not a state (0..%zd)",
                         (long long)f.w, (long long)f.v, (long long)f.s, S - 1);
            break;
        case E_T_MASS:
            raise_with_number("_step_kernel.step: T[%zd] row %lld (%lld entries) has no positive finite mass (sum %s)",
                              f.x, a, (long long)f.s, (long long)f.v);
            break;
        case E_O_MASS:
            raise_with_number("_step_kernel.step: O[%zd, %lld, :] (reached from state %lld) has no positive finite mass "
                              "(sum %s)", f.x, a, (long long)f.v, (long long)f.s);
            break;
        }
    }
done:
    release_all(all, sizeof all / sizeof all[0]);
    return ret;
}

/* row_tables(indptr, data, mass, ends, peaks): mass[s] = row s's entries summed left to right in
 * double, exactly as step sums them; for each grid position j = b * BLOCK of data inside a row:
 * ends[b] = that row's running sum before j, peaks[b] = its largest running sum over
 * j..min(j + BLOCK, row end) - 1 (positions outside every row: ends 0, peaks -inf). indptr must
 * be non-decreasing and within data. */
static PyObject *row_tables(PyObject *Py_UNUSED(self), PyObject *args) {
    PyObject *o_ptr, *o_dat, *o_out, *o_en, *o_pk;
    if (!PyArg_ParseTuple(args, "OOOOO:row_tables", &o_ptr, &o_dat, &o_out, &o_en, &o_pk)) return NULL;
    Py_buffer ptr = {0}, dat = {0}, out = {0}, en = {0}, pk = {0};
    Py_buffer *all[] = {&ptr, &dat, &out, &en, &pk};
    PyObject *ret = NULL;
    int kp, kd;
    if ((kp = take("row_tables", o_ptr, &ptr, 0, 1, (1u << K_I32) | (1u << K_I64), "indptr")) < 0
        || (kd = take("row_tables", o_dat, &dat, 0, 1, (1u << K_F32) | (1u << K_F64), "data")) < 0
        || take("row_tables", o_out, &out, 1, 1, 1u << K_F64, "mass") < 0
        || take("row_tables", o_en, &en, 1, 1, 1u << K_F64, "ends") < 0
        || take("row_tables", o_pk, &pk, 1, 1, 1u << K_F64, "peaks") < 0)
        goto done;
    Py_ssize_t S = ptr.shape[0] - 1, nnz = dat.shape[0];
    if (S < 0 || out.shape[0] != S) {
        PyErr_Format(PyExc_ValueError, "_step_kernel.row_tables: mass has %zd entries, indptr %zd: expected one fewer",
                     out.shape[0], ptr.shape[0]);
        goto done;
    }
    if (en.shape[0] != nnz / BLOCK + 1 || pk.shape[0] != nnz / BLOCK + 1) {
        PyErr_Format(PyExc_ValueError, "_step_kernel.row_tables: ends and peaks have %zd and %zd entries, expected "
                     "len(data) // BLOCK + 1 = %zd (BLOCK = %d)", en.shape[0], pk.shape[0], nnz / BLOCK + 1, BLOCK);
        goto done;
    }
    {
        double *mo = (double *)out.buf, *eo = (double *)en.buf, *po = (double *)pk.buf;
        Py_ssize_t bad = -1;
        int64_t blo = 0, bhi = 0, prev = 0;
        Py_BEGIN_ALLOW_THREADS
        for (Py_ssize_t b = 0; b <= nnz / BLOCK; b++) { eo[b] = 0.0; po[b] = -INFINITY; }
        for (Py_ssize_t s = 0; s < S; s++) {
            int64_t lo = ix_at(ptr.buf, kp, s), hi = ix_at(ptr.buf, kp, s + 1);
            if (lo < prev || hi < lo || hi > nnz) { bad = s; blo = lo; bhi = hi; break; }
            prev = hi;
            double c = 0.0;
            int64_t blk = -1;
            for (int64_t k = lo; k < hi; k++) {
                if (k % BLOCK == 0) { blk = k / BLOCK; eo[blk] = c; }
                c += val_at(dat.buf, kd, (Py_ssize_t)k);
                if (blk >= 0 && c > po[blk]) po[blk] = c;
            }
            mo[s] = c;
        }
        Py_END_ALLOW_THREADS
        if (bad >= 0)
            PyErr_Format(PyExc_ValueError, "_step_kernel.row_tables: the row of state %zd, indptr[%zd:%zd + 2] = [%lld, %lld], "
                         "is not a range within the %zd entries of data", bad, bad, bad,
                         (long long)blo, (long long)bhi, nnz);
        else {
            ret = Py_None;
            Py_INCREF(ret);
        }
    }
done:
    release_all(all, sizeof all / sizeof all[0]);
    return ret;
}

/* ---------------------------------------------------------------- DESPOT's expansion
 *
 * group_outcomes: the children of one expanded DESPOT node. Its N particles were stepped under
 * each of the A actions (next_states and observations, [A, N]); a child is an (action,
 * observation) pair and holds the particles that produced it, in the node's order. The children
 * come out in action order, then ascending observation, and their particles (next state and
 * scenario) are written to consecutive slices of states_out and scenarios_out: child g holds
 * positions group_start_out[g] .. group_start_out[g + 1] - 1. This is the stable sort of the
 * particles by (action, observation) that the search did with numpy before (a counting sort per
 * action when its observations span at most 65,536 values, a stable merge sort otherwise).
 */

/* Stable merge sort of idx[0..n) by key[idx[i]] (tmp: n scratch entries). */
static void merge_sort_by_key(int64_t *idx, int64_t *tmp, Py_ssize_t n, const int64_t *key) {
    for (Py_ssize_t width = 1; width < n; width *= 2) {
        for (Py_ssize_t lo = 0; lo < n; lo += 2 * width) {
            Py_ssize_t mid = lo + width < n ? lo + width : n, hi = lo + 2 * width < n ? lo + 2 * width : n;
            Py_ssize_t i = lo, j = mid, k = lo;
            while (i < mid && j < hi) tmp[k++] = key[idx[j]] < key[idx[i]] ? idx[j++] : idx[i++];
            while (i < mid) tmp[k++] = idx[i++];
            while (j < hi) tmp[k++] = idx[j++];
        }
        memcpy(idx, tmp, (size_t)n * sizeof *idx);
    }
}

#define COUNTING_SPAN 65536

static PyObject *group_outcomes(PyObject *Py_UNUSED(self), PyObject *args) {
    PyObject *o_nx, *o_ob, *o_sc, *o_so, *o_co, *o_ga, *o_go, *o_gs;
    if (!PyArg_ParseTuple(args, "OOOOOOOO:group_outcomes", &o_nx, &o_ob, &o_sc, &o_so, &o_co, &o_ga, &o_go, &o_gs))
        return NULL;
    Py_buffer nx = {0}, ob = {0}, sc = {0}, so = {0}, co = {0}, ga = {0}, go = {0}, gs = {0};
    Py_buffer *all[] = {&nx, &ob, &sc, &so, &co, &ga, &go, &gs};
    PyObject *ret = NULL;
    const unsigned I64 = 1u << K_I64;
    if (take("group_outcomes", o_nx, &nx, 0, 2, I64, "next_states") < 0
        || take("group_outcomes", o_ob, &ob, 0, 2, I64, "observations") < 0
        || take("group_outcomes", o_sc, &sc, 0, 1, I64, "scenarios") < 0
        || take("group_outcomes", o_so, &so, 1, 1, I64, "states_out") < 0
        || take("group_outcomes", o_co, &co, 1, 1, I64, "scenarios_out") < 0
        || take("group_outcomes", o_ga, &ga, 1, 1, I64, "group_action_out") < 0
        || take("group_outcomes", o_go, &go, 1, 1, I64, "group_obs_out") < 0
        || take("group_outcomes", o_gs, &gs, 1, 1, I64, "group_start_out") < 0)
        goto done;
    Py_ssize_t A = nx.shape[0], N = nx.shape[1];
    if (ob.shape[0] != A || ob.shape[1] != N) {
        PyErr_Format(PyExc_ValueError, "_step_kernel.group_outcomes: observations have shape (%zd, %zd), next_states "
                     "(%zd, %zd): expected the same [A, N]", ob.shape[0], ob.shape[1], A, N);
        goto done;
    }
    if (A < 1 || N < 1) {
        PyErr_Format(PyExc_ValueError, "_step_kernel.group_outcomes: next_states has shape (%zd, %zd): expected [A, N], "
                     "neither empty", A, N);
        goto done;
    }
    if (sc.shape[0] != N) {
        PyErr_Format(PyExc_ValueError, "_step_kernel.group_outcomes: scenarios has %zd entries, expected N = %zd (the "
                     "particles)", sc.shape[0], N);
        goto done;
    }
    if (so.shape[0] != A * N || co.shape[0] != A * N || ga.shape[0] != A * N || go.shape[0] != A * N
        || gs.shape[0] != A * N + 1) {
        PyErr_Format(PyExc_ValueError, "_step_kernel.group_outcomes: states_out, scenarios_out, group_action_out, "
                     "group_obs_out, group_start_out have %zd, %zd, %zd, %zd, %zd entries: expected A*N = %zd "
                     "(group_start_out: A*N + 1)", so.shape[0], co.shape[0], ga.shape[0], go.shape[0], gs.shape[0],
                     A * N);
        goto done;
    }
    {
        const int64_t *nxt = (const int64_t *)nx.buf, *obs = (const int64_t *)ob.buf, *scen = (const int64_t *)sc.buf;
        int64_t *st_out = (int64_t *)so.buf, *sc_out = (int64_t *)co.buf, *g_act = (int64_t *)ga.buf;
        int64_t *g_obs = (int64_t *)go.buf, *g_start = (int64_t *)gs.buf;
        /* One sort for every action: counting over the observations' whole range when it spans at
         * most COUNTING_SPAN values (the scratch is then its counts), else a stable merge sort of the
         * indices (scratch: 2 N). The span is computed in unsigned: observations may be any int64. */
        int64_t lo = obs[0], hi = obs[0];
        for (Py_ssize_t i = 1; i < A * N; i++) {
            if (obs[i] < lo) lo = obs[i];
            if (obs[i] > hi) hi = obs[i];
        }
        uint64_t span = (uint64_t)hi - (uint64_t)lo;
        int counting = span < COUNTING_SPAN;
        Py_ssize_t V = counting ? (Py_ssize_t)span + 1 : 0;
        int64_t *work = (int64_t *)PyMem_RawMalloc((size_t)(counting ? V + 1 : 2 * N) * sizeof(int64_t));
        if (work == NULL) {
            PyErr_NoMemory();
            goto done;
        }
        Py_ssize_t G = 0, pos = 0;
        Py_BEGIN_ALLOW_THREADS
        for (Py_ssize_t a = 0; a < A; a++) {
            const int64_t *row = obs + a * N, *nrow = nxt + a * N;
            Py_ssize_t first = pos;
            if (counting) {
                int64_t *count = work;
                memset(count, 0, (size_t)(V + 1) * sizeof *count);
                for (Py_ssize_t i = 0; i < N; i++) count[row[i] - lo + 1]++;
                for (Py_ssize_t v = 0; v < V; v++) {       /* count[v] becomes the start of value v */
                    if (count[v + 1] > 0) {
                        g_act[G] = a;
                        g_obs[G] = lo + v;
                        g_start[G] = first + count[v];
                        G++;
                    }
                    count[v + 1] += count[v];
                }
                for (Py_ssize_t i = 0; i < N; i++) {
                    int64_t at = first + count[row[i] - lo]++;
                    st_out[at] = nrow[i];
                    sc_out[at] = scen[i];
                }
            } else {
                int64_t *idx = work, *tmp = work + N;
                for (Py_ssize_t i = 0; i < N; i++) idx[i] = i;
                merge_sort_by_key(idx, tmp, N, row);
                for (Py_ssize_t i = 0; i < N; i++) {
                    int64_t j = idx[i];
                    if (i == 0 || row[j] != row[idx[i - 1]]) {
                        g_act[G] = a;
                        g_obs[G] = row[j];
                        g_start[G] = first + i;
                        G++;
                    }
                    st_out[first + i] = nrow[j];
                    sc_out[first + i] = scen[j];
                }
            }
            pos += N;
        }
        g_start[G] = pos;
        Py_END_ALLOW_THREADS
        PyMem_RawFree(work);
        ret = PyLong_FromSsize_t(G);
    }
done:
    release_all(all, sizeof all / sizeof all[0]);
    return ret;
}

/* group_max_means: the value of α-vector bounds at each of G particle sets. The sets are
 * consecutive slices of states (set g: positions starts[g] .. starts[g + 1] - 1, none empty);
 * table is [S, C] (a column per vector: an upper bound's Q or a lower bound's α-vectors); out[g] is
 * the largest over the columns of the column's mean over the set's particles. Each column sum is
 * numpy's np.add.reduceat(table[states], starts[:-1], axis=0) to the bit: the set's first row,
 * then the rest added as numpy's pairwise summation adds (blocks of at most 128 with eight
 * running sums), so the bounds are those the search computed with numpy before; then the sum over
 * the set's size, and the first largest (NaN if any mean is NaN, as ndarray.max). */
static double pairwise_gather(const double *table, Py_ssize_t C, Py_ssize_t c, const int64_t *s, Py_ssize_t n) {
    if (n < 8) {
        double res = 0.;
        for (Py_ssize_t i = 0; i < n; i++) res += table[s[i] * C + c];
        return res;
    }
    if (n <= 128) {
        double r[8], res;
        Py_ssize_t i;
        for (int j = 0; j < 8; j++) r[j] = table[s[j] * C + c];
        for (i = 8; i < n - (n % 8); i += 8)
            for (int j = 0; j < 8; j++) r[j] += table[s[i + j] * C + c];
        res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for (; i < n; i++) res += table[s[i] * C + c];
        return res;
    }
    Py_ssize_t n2 = n / 2;
    n2 -= n2 % 8;
    return pairwise_gather(table, C, c, s, n2) + pairwise_gather(table, C, c, s + n2, n - n2);
}

static PyObject *group_max_means(PyObject *Py_UNUSED(self), PyObject *args) {
    PyObject *o_st, *o_gs, *o_tb, *o_out;
    if (!PyArg_ParseTuple(args, "OOOO:group_max_means", &o_st, &o_gs, &o_tb, &o_out)) return NULL;
    Py_buffer st = {0}, gs = {0}, tb = {0}, out = {0};
    Py_buffer *all[] = {&st, &gs, &tb, &out};
    PyObject *ret = NULL;
    const unsigned I64 = 1u << K_I64, F64 = 1u << K_F64;
    if (take("group_max_means", o_st, &st, 0, 1, I64, "states") < 0
        || take("group_max_means", o_gs, &gs, 0, 1, I64, "starts") < 0
        || take("group_max_means", o_tb, &tb, 0, 2, F64, "table") < 0
        || take("group_max_means", o_out, &out, 1, 1, F64, "out") < 0)
        goto done;
    Py_ssize_t M = st.shape[0], G = gs.shape[0] - 1, S = tb.shape[0], C = tb.shape[1];
    if (G < 0 || out.shape[0] != G) {
        PyErr_Format(PyExc_ValueError, "_step_kernel.group_max_means: out has %zd entries, starts %zd: expected one fewer",
                     out.shape[0], gs.shape[0]);
        goto done;
    }
    if (C < 1) {
        PyErr_Format(PyExc_ValueError, "_step_kernel.group_max_means: table has shape (%zd, %zd): expected [S, C] with "
                     "C >= 1", S, C);
        goto done;
    }
    {
        const int64_t *s = (const int64_t *)st.buf, *g = (const int64_t *)gs.buf;
        const double *t = (const double *)tb.buf;
        double *o = (double *)out.buf;
        Py_ssize_t bad_set = -1, bad_at = -1;
        Py_BEGIN_ALLOW_THREADS
        if (G > 0 && (g[0] != 0 || g[G] != M)) bad_set = G;
        for (Py_ssize_t k = 0; bad_set < 0 && k < G; k++)
            if (g[k + 1] <= g[k]) bad_set = k;
        for (Py_ssize_t i = 0; bad_set < 0 && i < M; i++)
            if (s[i] < 0 || s[i] >= S) { bad_at = i; break; }
        for (Py_ssize_t k = 0; bad_set < 0 && bad_at < 0 && k < G; k++) {
            const int64_t *p = s + g[k];
            Py_ssize_t n = (Py_ssize_t)(g[k + 1] - g[k]);
            double best = 0.0;
            for (Py_ssize_t c = 0; c < C; c++) {
                double sum = n > 1 ? t[p[0] * C + c] + pairwise_gather(t, C, c, p + 1, n - 1) : t[p[0] * C + c];
                double mean = sum / (double)n;
                if (c == 0 || mean > best || isnan(mean)) best = mean;
                if (isnan(best)) break;
            }
            o[k] = best;
        }
        Py_END_ALLOW_THREADS
        if (bad_set == G)
            PyErr_Format(PyExc_ValueError, "_step_kernel.group_max_means: starts must run from 0 to len(states) = %zd, "
                         "got %lld .. %lld", M, (long long)g[0], (long long)g[G]);
        else if (bad_set >= 0)
            PyErr_Format(PyExc_ValueError, "_step_kernel.group_max_means: set %zd is empty or reversed (starts[%zd] = %lld, "
                         "starts[%zd] = %lld)", bad_set, bad_set, (long long)g[bad_set], bad_set + 1,
                         (long long)g[bad_set + 1]);
        else if (bad_at >= 0)
            PyErr_Format(PyExc_ValueError, "_step_kernel.group_max_means: states[%zd] = %lld is not a row of table (0..%zd)",
                         bad_at, (long long)s[bad_at], S - 1);
        else {
            ret = Py_None;
            Py_INCREF(ret);
        }
    }
done:
    release_all(all, sizeof all / sizeof all[0]);
    return ret;
}

/* rock_tours: RockSample's tour policies valued on G particle sets (pearl_pomdp/online/rocksample.py,
 * RockSampleBounds). Set g is states[starts[g]] .. states[starts[g + 1] - 1], all at one cell (the
 * rover's position is known: the set's first state gives it); a state is (cell << k) | bits, rock i
 * good when bit i is set. A tour (candidate c of set g) visits the rocks of visit[g, c], nearest first
 * by Manhattan distance (the lower index on a tie), then drives East off the grid (+10). At a rock
 * of blind[g, c] it samples at once (+10 good, -10 bad, one step); at any other it checks first
 * (one step; exact at distance 0) and samples only a good rock. Each particle's discounted return,
 * gamma^t read from powers[t], is summed over the set in order and divided by the set's size;
 * out[g] is the largest over the candidates (the first largest). The rocks' order is found again
 * for every set and candidate: k^2 comparisons at most, less than reading its particles.
 * Why C: the checking tours are valued particle by particle (a particle's sample times depend on
 * how many good rocks it sampled before), and numpy's [particles, k] temporaries cost ~2 ms an
 * expansion on RockSample(11,11), three times the rest of the search. */
static PyObject *rock_tours(PyObject *Py_UNUSED(self), PyObject *args) {
    PyObject *o_st, *o_gs, *o_rk, *o_vi, *o_bl, *o_pw, *o_out;
    Py_ssize_t k, n;
    if (!PyArg_ParseTuple(args, "OOnnOOOOO:rock_tours", &o_st, &o_gs, &k, &n, &o_rk, &o_vi, &o_bl, &o_pw, &o_out))
        return NULL;
    Py_buffer st = {0}, gs = {0}, rk = {0}, vi = {0}, bl = {0}, pw = {0}, out = {0};
    Py_buffer *all[] = {&st, &gs, &rk, &vi, &bl, &pw, &out};
    PyObject *ret = NULL;
    const unsigned I64 = 1u << K_I64, F64 = 1u << K_F64;
    if (take("rock_tours", o_st, &st, 0, 1, I64, "states") < 0
        || take("rock_tours", o_gs, &gs, 0, 1, I64, "starts") < 0
        || take("rock_tours", o_rk, &rk, 0, 2, I64, "rocks") < 0
        || take("rock_tours", o_vi, &vi, 0, 2, I64, "visit") < 0
        || take("rock_tours", o_bl, &bl, 0, 2, I64, "blind") < 0
        || take("rock_tours", o_pw, &pw, 0, 1, F64, "powers") < 0
        || take("rock_tours", o_out, &out, 1, 1, F64, "out") < 0)
        goto done;
    Py_ssize_t M = st.shape[0], G = gs.shape[0] - 1, C = vi.shape[1], T = pw.shape[0];
    if (k < 1 || k > 62 || n < 1 || rk.shape[0] != k || rk.shape[1] != 2) {
        PyErr_Format(PyExc_ValueError, "_step_kernel.rock_tours: rocks has shape (%zd, %zd) with k = %zd, n = %zd: "
                     "expected [k, 2] with 1 <= k <= 62 and n >= 1", rk.shape[0], rk.shape[1], k, n);
        goto done;
    }
    if (G < 0 || out.shape[0] != G || vi.shape[0] != G || bl.shape[0] != G || bl.shape[1] != C || C < 1) {
        PyErr_Format(PyExc_ValueError, "_step_kernel.rock_tours: out has %zd entries, visit (%zd, %zd), blind (%zd, %zd), "
                     "starts %zd: expected G = len(starts) - 1 rows each and C >= 1 candidates", out.shape[0],
                     vi.shape[0], C, bl.shape[0], bl.shape[1], gs.shape[0]);
        goto done;
    }
    {
        const int64_t *s = (const int64_t *)st.buf, *g = (const int64_t *)gs.buf, *r = (const int64_t *)rk.buf;
        const int64_t *visit = (const int64_t *)vi.buf, *blind = (const int64_t *)bl.buf;
        const double *powers = (const double *)pw.buf;
        double *o = (double *)out.buf;
        Py_ssize_t bad_set = -1, bad_cell = -1, bad_rock = -1, short_powers = -1;
        Py_BEGIN_ALLOW_THREADS
        if (G > 0 && (g[0] != 0 || g[G] != M)) bad_set = G;
        for (Py_ssize_t q = 0; bad_set < 0 && q < G; q++)
            if (g[q + 1] <= g[q]) bad_set = q;
        for (Py_ssize_t i = 0; bad_set < 0 && i < k; i++)
            if (r[2 * i] < 0 || r[2 * i] >= n || r[2 * i + 1] < 0 || r[2 * i + 1] >= n) { bad_rock = i; break; }
        for (Py_ssize_t q = 0; bad_set < 0 && bad_rock < 0 && bad_cell < 0 && short_powers < 0 && q < G; q++) {
            int64_t cell = s[g[q]] >> k;
            if (s[g[q]] < 0 || cell >= (int64_t)n * n) { bad_cell = q; break; }
            double best = 0.0;
            for (Py_ssize_t c = 0; c < C && short_powers < 0; c++) {
                int64_t todo = visit[q * C + c] & (((int64_t)1 << k) - 1), at_blind = blind[q * C + c];
                int order[62], moved[62];
                int count = 0;
                int64_t x = cell % n, y = cell / n;
                while (todo) {
                    int pick = -1;
                    int64_t d_pick = 0;
                    for (int i = 0; i < k; i++)
                        if (todo >> i & 1) {
                            int64_t d = llabs(r[2 * i] - x) + llabs(r[2 * i + 1] - y);
                            if (pick < 0 || d < d_pick) { pick = i; d_pick = d; }
                        }
                    todo &= ~((int64_t)1 << pick);
                    order[count] = pick;
                    moved[count++] = (int)d_pick;
                    x = r[2 * pick];
                    y = r[2 * pick + 1];
                }
                int64_t to_exit = n - 1 - x, longest = to_exit;
                for (int j = 0; j < count; j++) longest += moved[j] + 2;   /* a check and a sample each */
                if (longest >= T) { short_powers = q; break; }
                double sum = 0.0;
                for (int64_t p = g[q]; p < g[q + 1]; p++) {
                    int64_t t = 0, bits = s[p];
                    double v = 0.0;
                    for (int j = 0; j < count; j++) {
                        int i = order[j];
                        int good = (int)(bits >> i & 1);
                        t += moved[j];
                        if (at_blind >> i & 1) {
                            v += good ? 10.0 * powers[t] : -10.0 * powers[t];
                            t += 1;
                        } else {
                            t += 1;                       /* the check */
                            if (good) { v += 10.0 * powers[t]; t += 1; }
                        }
                    }
                    sum += v + 10.0 * powers[t + to_exit];
                }
                double mean = sum / (double)(g[q + 1] - g[q]);
                if (c == 0 || mean > best) best = mean;
            }
            o[q] = best;
        }
        Py_END_ALLOW_THREADS
        if (bad_set == G)
            PyErr_Format(PyExc_ValueError, "_step_kernel.rock_tours: starts must run from 0 to len(states) = %zd, "
                         "got %lld .. %lld", M, (long long)g[0], (long long)g[G]);
        else if (bad_set >= 0)
            PyErr_Format(PyExc_ValueError, "_step_kernel.rock_tours: set %zd is empty or reversed (starts[%zd] = %lld, "
                         "starts[%zd] = %lld)", bad_set, bad_set, (long long)g[bad_set], bad_set + 1,
                         (long long)g[bad_set + 1]);
        else if (bad_rock >= 0)
            PyErr_Format(PyExc_ValueError, "_step_kernel.rock_tours: rock %zd at (%lld, %lld) is off the %zd x %zd grid",
                         bad_rock, (long long)r[2 * bad_rock], (long long)r[2 * bad_rock + 1], n, n);
        else if (bad_cell >= 0)
            PyErr_Format(PyExc_ValueError, "_step_kernel.rock_tours: set %zd's first state %lld is not on the grid (cell "
                         "= state >> k must be below n * n = %zd)", bad_cell, (long long)s[g[bad_cell]], n * n);
        else if (short_powers >= 0)
            PyErr_Format(PyExc_ValueError, "_step_kernel.rock_tours: powers has %zd entries, too few for set %zd's tour",
                         T, short_powers);
        else {
            ret = Py_None;
            Py_INCREF(ret);
        }
    }
done:
    release_all(all, sizeof all / sizeof all[0]);
    return ret;
}

/* ---------------------------------------------------------------- a factored domain's T[a]
 *
 * product_rows: the CSR entries of T[a] of a factored domain (pearl_pomdp/model/factored.py,
 * FactoredDomain.transition_matrix), where T[a][s, s'] = prod_f P(s'_f | s, a). For every feature
 * f (F of them) and state s, the non-zero factors P(s'_f = v | s, a) are entries ptrs[f, s] ..
 * ptrs[f, s + 1] - 1 of values (v) and probs (p), values ascending; features may share the arrays
 * (each row of ptrs points into them). State s's row holds one entry per choice of a factor of
 * every feature, in lexicographic order with feature 0 most significant: column sum_f v_f *
 * strides[f], probability ((1 * p_0) * p_1) * ... * p_{F-1}, multiplied left to right (the order
 * the numpy build before this kernel multiplied in, so the numbers are the same bit for bit).
 * With the strides of the state space's mixed radix (feature 0's largest) the columns ascend.
 * indptr [S+1] is the caller's (each row's size, the product of its features' factor counts,
 * summed); it is checked, and so is every pointer and column: bad input is a ValueError.
 * Why C: the numpy build expanded the rows one feature at a time through a dozen temporaries
 * of up to nnz entries; on the ward (233,280 states, 1.3 M entries per action, 15 actions) that
 * was ~2-3 s of a 6 s compilation, which each node that loads the ward pays at start-up. */
static PyObject *product_rows(PyObject *Py_UNUSED(self), PyObject *args) {
    PyObject *o_pt, *o_va, *o_pr, *o_sd, *o_ip, *o_ix, *o_da;
    if (!PyArg_ParseTuple(args, "OOOOOOO:product_rows", &o_pt, &o_va, &o_pr, &o_sd, &o_ip, &o_ix, &o_da)) return NULL;
    Py_buffer pt = {0}, va = {0}, pr = {0}, sd = {0}, ip = {0}, ix = {0}, da = {0};
    Py_buffer *all[] = {&pt, &va, &pr, &sd, &ip, &ix, &da};
    PyObject *ret = NULL;
    int64_t *work = NULL;
    double *partial = NULL;
    int kx = K_I64;
    if (take("product_rows", o_pt, &pt, 0, 2, 1u << K_I64, "ptrs") < 0
        || take("product_rows", o_va, &va, 0, 1, 1u << K_I64, "values") < 0
        || take("product_rows", o_pr, &pr, 0, 1, 1u << K_F64, "probs") < 0
        || take("product_rows", o_sd, &sd, 0, 1, 1u << K_I64, "strides") < 0
        || take("product_rows", o_ip, &ip, 0, 1, 1u << K_I64, "indptr") < 0
        || (kx = take("product_rows", o_ix, &ix, 1, 1, (1u << K_I32) | (1u << K_I64), "indices_out")) < 0
        || take("product_rows", o_da, &da, 1, 1, 1u << K_F64, "data_out") < 0)
        goto done;
    Py_ssize_t F = pt.shape[0], S = pt.shape[1] - 1, n = va.shape[0], nnz = ix.shape[0];
    if (S < 0 || sd.shape[0] != F || pr.shape[0] != n || ip.shape[0] != S + 1 || da.shape[0] != nnz) {
        PyErr_Format(PyExc_ValueError, "_step_kernel.product_rows: shapes disagree: ptrs [%zd, %zd], strides [%zd], "
                     "values [%zd], probs [%zd], indptr [%zd], indices_out [%zd], data_out [%zd] (expected ptrs [F, S+1], "
                     "strides [F], probs as values, indptr [S+1], data_out as indices_out)", F, pt.shape[1],
                     sd.shape[0], n, pr.shape[0], ip.shape[0], nnz, da.shape[0]);
        goto done;
    }
    if (kx == K_I32 && S > INT32_MAX) {
        PyErr_Format(PyExc_ValueError, "_step_kernel.product_rows: %zd states do not fit int32 indices_out", S);
        goto done;
    }
    /* per feature: the current entry, its row's first and end entry; the running products */
    work = malloc(sizeof(int64_t) * (size_t)(3 * F + F + 1));
    partial = malloc(sizeof(double) * (size_t)(F + 1));
    if (work == NULL || partial == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    {
        const int64_t *P = (const int64_t *)pt.buf, *V = (const int64_t *)va.buf, *D = (const int64_t *)sd.buf;
        const int64_t *IP = (const int64_t *)ip.buf;
        const double *PR = (const double *)pr.buf;
        double *out = (double *)da.buf;
        int64_t *at = work, *lo = work + F, *hi = work + 2 * F, *col = work + 3 * F;
        Py_ssize_t bad_state = -1, bad_feature = -1, bad_size = -1, bad_column = -1;
        int64_t bad_col = 0;
        Py_BEGIN_ALLOW_THREADS
        if (IP[0] != 0 || IP[S] != nnz) bad_size = S;
        for (Py_ssize_t s = 0; s < S && bad_state < 0 && bad_size < 0 && bad_column < 0; s++) {
            int64_t size = 1;
            for (Py_ssize_t f = 0; f < F; f++) {
                lo[f] = P[f * (S + 1) + s];
                hi[f] = P[f * (S + 1) + s + 1];
                if (lo[f] < 0 || hi[f] < lo[f] || hi[f] > n) { bad_state = s; bad_feature = f; break; }
                size *= hi[f] - lo[f];
            }
            if (bad_state >= 0) break;
            int64_t pos = IP[s];
            if (IP[s + 1] - pos != size || pos < 0 || IP[s + 1] > nnz) { bad_size = s; break; }
            if (size == 0) continue;
            partial[0] = 1.0;
            col[0] = 0;
            for (Py_ssize_t f = 0; f < F; f++) at[f] = lo[f];
            Py_ssize_t from = 0;   /* the first feature whose entry changed: the products up to it stand */
            for (;;) {
                for (Py_ssize_t f = from; f < F; f++) {
                    partial[f + 1] = partial[f] * PR[at[f]];
                    col[f + 1] = col[f] + V[at[f]] * D[f];
                }
                if (col[F] < 0 || col[F] >= S) { bad_column = s; bad_col = col[F]; break; }
                if (kx == K_I32) ((int32_t *)ix.buf)[pos] = (int32_t)col[F];
                else ((int64_t *)ix.buf)[pos] = col[F];
                out[pos++] = partial[F];
                Py_ssize_t f = F - 1;   /* the next entry: the last feature's next factor, carried leftwards */
                while (f >= 0 && ++at[f] >= hi[f]) {
                    at[f] = lo[f];
                    f--;
                }
                if (f < 0) break;
                from = f;
            }
        }
        Py_END_ALLOW_THREADS
        if (bad_state >= 0)
            PyErr_Format(PyExc_ValueError, "_step_kernel.product_rows: feature %zd's factors of state %zd, ptrs[%zd, %zd:%zd + 2] "
                         "= [%lld, %lld], are not a range within the %zd entries of values", bad_feature, bad_state,
                         bad_feature, bad_state, bad_state, (long long)lo[bad_feature], (long long)hi[bad_feature], n);
        else if (bad_size >= 0)
            PyErr_Format(PyExc_ValueError, "_step_kernel.product_rows: indptr does not hold the rows' sizes (the products of "
                         "their features' factor counts) from 0 to len(indices_out) = %zd: first wrong at state %zd",
                         nnz, bad_size);
        else if (bad_column >= 0)
            PyErr_Format(PyExc_ValueError, "_step_kernel.product_rows: state %zd has an entry in column %lld, not a state "
                         "(0 .. %zd)", bad_column, (long long)bad_col, S - 1);
        else {
            ret = Py_None;
            Py_INCREF(ret);
        }
    }
done:
    free(work);
    free(partial);
    release_all(all, sizeof all / sizeof all[0]);
    return ret;
}

static PyMethodDef methods[] = {
    {"row_tables", row_tables, METH_VARARGS,
     "row_tables(indptr, data, mass, ends, peaks) -> None\n\n"
     "The tables step reads for T[action] as CSR (indptr [S+1] int32 or int64, non-decreasing; data float32 or\n"
     "float64): mass [S] float64 = each row summed as step sums it; ends, peaks [len(data) // BLOCK + 1] float64\n"
     "(see the file's comment). Raises ValueError on bad input."},
    {"step", step, METH_VARARGS,
     "step(indptr, indices, data, mass, ends, peaks, O, R, action, states, uniforms, next_out, obs_out,\n"
     "     reward_out) -> None\n\n"
     "One step of N particles under `action` (see the file's comment for the definition): T[action] as CSR\n"
     "(indptr [S+1], indices [nnz] int32 or int64; data [nnz] float32 or float64) with its row_tables (mass,\n"
     "ends, peaks), O [A, S, Z] float32 or\n"
     "float64, R [S, A] float64, states [N] int64, uniforms [N, >=2] float64 in [0, 1); writes next_out [N]\n"
     "int64, obs_out [N] int64, reward_out [N] float64. Raises ValueError on bad input."},
    {"group_outcomes", group_outcomes, METH_VARARGS,
     "group_outcomes(next_states, observations, scenarios, states_out, scenarios_out, group_action_out,\n"
     "               group_obs_out, group_start_out) -> int\n\n"
     "A DESPOT expansion's children (see the comment above the function): next_states, observations [A, N]\n"
     "int64, scenarios [N] int64; writes the particles grouped by (action, observation), stable, to states_out\n"
     "and scenarios_out [A*N], and per child its action, observation and first position to group_action_out,\n"
     "group_obs_out [A*N] and group_start_out [A*N + 1] (the last start: A*N). Returns the number of children.\n"
     "Raises ValueError on bad input."},
    {"group_max_means", group_max_means, METH_VARARGS,
     "group_max_means(states, starts, table, out) -> None\n\n"
     "out[g] = max over the columns of table [S, C] float64 of the column's mean over states[starts[g]:starts[g+1]]\n"
     "(states int64, starts [G+1] int64 from 0 to len(states), no set empty; sums as numpy's add.reduceat).\n"
     "Raises ValueError on bad input."},
    {"rock_tours", rock_tours, METH_VARARGS,
     "rock_tours(states, starts, k, n, rocks, visit, blind, powers, out) -> None\n\n"
     "RockSample's tour policies on particle sets (see the comment above the function): states int64 (cell << k |\n"
     "bits), starts [G+1] int64 from 0 to len(states), no set empty, rocks [k, 2] int64 (x, y), visit and blind\n"
     "[G, C] int64 rock masks per candidate tour, powers [T] float64 (gamma^t); out[g] = the best candidate's\n"
     "mean discounted return over set g. Raises ValueError on bad input."},
    {"product_rows", product_rows, METH_VARARGS,
     "product_rows(ptrs, values, probs, strides, indptr, indices_out, data_out) -> None\n\n"
     "A factored domain's T[a] as CSR (see the comment above the function): ptrs [F, S+1] int64, each feature's\n"
     "factors of each state as a range of values [n] int64 and probs [n] float64, strides [F] int64, indptr [S+1]\n"
     "int64 (the rows' sizes summed); writes the columns to indices_out [nnz] int32 or int64 and the products to\n"
     "data_out [nnz] float64. Raises ValueError on bad input."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_step_kernel",
                                    "The online planner's loops in C: ExplicitModel.step (inverse-CDF draws per row), DESPOT's grouping of an "
                                    "expansion's outcomes and the alpha-vector bounds of the groups; and a factored domain's T[a] rows "
                                    "(product_rows), which every planner's compilation reads.", -1,
                                    methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__step_kernel(void) {
    PyObject *m = PyModule_Create(&module);
    if (m != NULL && PyModule_AddIntConstant(m, "BLOCK", BLOCK) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}

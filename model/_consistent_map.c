/* flexcal.model._consistent_map: the consistent model's map at one pose, the six chains as
 * the lanes of one vector (docs/model.md 10, "Session 42").
 *
 * flexcal_consistent_terms computes what ``_numba_consistent._terms`` computes (the chains'
 * shortening r, axial inputs u, tensions n and the second-order wrench ``force``) with the same
 * formulas in the same order, each chain's arithmetic in one lane of an 8-wide vector (six
 * lanes used). numba does not vectorize across the chains (its LLVM pass that would, SLP, is
 * off: numba PR 8852), so ``_terms`` runs one chain after another on scalars; here every
 * product runs on the six chains at once. GCC's vector extensions give the lanes; with
 * target_clones the loader picks AVX-512, AVX2 or the baseline at run time. The numba kernel
 * calls this through ``numba.types.ExternalFunction`` (model/consistent_native.py); numba's
 * ``_terms`` stays as the reference and the fallback where this module is not built.
 *
 * Layout (model/consistent.py ``lane_rows``): per candidate ``n_rows`` rows of 8 lanes:
 * rows row * WIDTH + col hold ``pack_chains``' entry [chain, row, col] in lane ``chain``
 * (the same row constants as ``_numba_consistent``); then point_b (3 rows), the axial
 * stiffness (1) and the lateral defect's coefficients (n_terms rows).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>

typedef double lanes_t __attribute__((vector_size(64)));
typedef double lanes_u __attribute__((vector_size(64), aligned(8)));  /* numpy's rows: 8-byte aligned */

enum {
    WIDTH = 8, J_COL = 0, R_ROW = 6, S_COL = 9, K_COL = 15, T_COL = 21, J_ROW = 27, W_COL = 33, GAIN = 36,
    AXIAL_ROW = 37, K_ROW0 = 38, N_PACK = 39,
    POINT = N_PACK * WIDTH, AXIAL = POINT + 3, DEFECT = AXIAL + 1
};

#if defined(__GNUC__) && defined(__x86_64__) && !defined(__clang__)
#define CLONES __attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
#else
#define CLONES
#endif

static inline double lane_sum(lanes_t a)
{
    return ((a[0] + a[1]) + (a[2] + a[3])) + ((a[4] + a[5]) + (a[6] + a[7]));
}

#define P(row, col) (L[(row) * WIDTH + (col)])

CLONES
void flexcal_consistent_terms(long cand, long n_rows, const double *lanes, const double *x, const double *c,
                              const double *command, const double *x0, const double *weight, long n_terms,
                              const long *defect_index, long symmetric, double *r, double *u, double *n,
                              double *force)
{
    const lanes_u *L = (const lanes_u *)(lanes + cand * n_rows * WIDTH);
    const double t0 = x[3], t1 = x[4], t2 = x[5];
    const double tt = t0 * t0 + t1 * t1 + t2 * t2;
    double f[6] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
    /* the weight W at the centre of gravity r turns with the frame: -d ext_r / d theta^T W */
    const double *w = weight + 6 * cand;
    const double tw = t0 * w[0] + t1 * w[1] + t2 * w[2];
    const double tr = t0 * w[3] + t1 * w[4] + t2 * w[5];
    const double rw = w[3] * w[0] + w[4] * w[1] + w[5] * w[2];
    f[3] -= 0.5 * (w[3] * tw + tr * w[0] - 2.0 * t0 * rw);
    f[4] -= 0.5 * (w[4] * tw + tr * w[1] - 2.0 * t1 * rw);
    f[5] -= 0.5 * (w[5] * tw + tr * w[2] - 2.0 * t2 * rw);

    const lanes_t pb0 = L[POINT], pb1 = L[POINT + 1], pb2 = L[POINT + 2];
    const lanes_t tp = t0 * pb0 + t1 * pb1 + t2 * pb2;
    const lanes_t e0 = 0.5 * (t0 * tp - pb0 * tt);  /* ext = 1/2 theta x (theta x p_j) */
    const lanes_t e1 = 0.5 * (t1 * tp - pb1 * tt);
    const lanes_t e2 = 0.5 * (t2 * tp - pb2 * tt);
    lanes_t ec[3], d[6], s[6];
    for (int k = 0; k < 3; k++)
        ec[k] = e0 * P(R_ROW, k) + e1 * P(R_ROW + 1, k) + e2 * P(R_ROW + 2, k);
    for (int k = 0; k < 6; k++)
        d[k] = x[0] * P(J_COL, k) + x[1] * P(J_COL + 1, k) + x[2] * P(J_COL + 2, k) + x[3] * P(J_COL + 3, k)
               + x[4] * P(J_COL + 4, k) + x[5] * P(J_COL + 5, k) + (k < 3 ? ec[k] : (lanes_t){0});
    for (int k = 0; k < 6; k++)
        s[k] = d[0] * P(S_COL, k) + d[1] * P(S_COL + 1, k) + d[2] * P(S_COL + 2, k) + d[3] * P(S_COL + 3, k)
               + d[4] * P(S_COL + 4, k) + d[5] * P(S_COL + 5, k);
    const lanes_t rr = d[0] * s[0] + d[1] * s[1] + d[2] * s[2] + d[3] * s[3] + d[4] * s[4] + d[5] * s[5];
    const double *x0c = x0 + 3 * cand;
    const lanes_t offset = {0.0, 0.0, 0.0, command[0] + x0c[0] + c[0], command[1] + x0c[1] + c[1],
                            command[2] + x0c[2] + c[2], 0.0, 0.0};
    const lanes_t uj = -rr + offset;

    /* the lateral compatibility defect m_c = sum_t q_t d_a d_b (c = y..rz) */
    const lanes_u *q = L + DEFECT;
    lanes_t m[6] = {{0}};
    if (symmetric) {  /* _numba_consistent.SYMMETRIC_DEFECT's terms in its order */
        m[1] = q[0] * d[2] * d[3] + q[1] * d[3] * d[4];
        m[2] = q[2] * d[1] * d[3] + q[3] * d[3] * d[5];
        m[3] = q[4] * d[1] * d[2] + q[5] * d[1] * d[4] + q[6] * d[2] * d[5] + q[7] * d[4] * d[5];
        m[4] = q[8] * d[1] * d[3] + q[9] * d[3] * d[5];
        m[5] = q[10] * d[2] * d[3] + q[11] * d[3] * d[4];
    } else {
        for (long t = 0; t < n_terms; t++)
            m[defect_index[3 * t]] += q[t] * d[defect_index[3 * t + 1]] * d[defect_index[3 * t + 2]];
    }
    /* K m, and the lateral chain force (K e)_c = K m - K[:, 0] u + K D (c = y..rz) */
    lanes_t k[6], fl[6];
    for (int i = 0; i < 6; i++) {
        k[i] = m[1] * P(K_COL + 1, i) + m[2] * P(K_COL + 2, i) + m[3] * P(K_COL + 3, i) + m[4] * P(K_COL + 4, i)
               + m[5] * P(K_COL + 5, i);
        fl[i] = (k[i] - P(K_COL, i) * uj)
                + (d[0] * P(K_COL, i) + d[1] * P(K_COL + 1, i) + d[2] * P(K_COL + 2, i) + d[3] * P(K_COL + 3, i)
                   + d[4] * P(K_COL + 4, i) + d[5] * P(K_COL + 5, i));
    }
    const lanes_t axial = L[AXIAL];
    lanes_t load = -axial * uj + k[0];
    load += P(GAIN, 0) * x[0] + P(GAIN, 1) * x[1] + P(GAIN, 2) * x[2] + P(GAIN, 3) * x[3] + P(GAIN, 4) * x[4]
            + P(GAIN, 5) * x[5];
    load += P(AXIAL_ROW, 0) * ec[0] + P(AXIAL_ROW, 1) * ec[1] + P(AXIAL_ROW, 2) * ec[2];
    /* the chain's own P-delta inside: tension N (1 + k q), shortening D^T (S + N T) D */
    lanes_t tq[6];
    tq[0] = (lanes_t){0};
    for (int i = 1; i < 6; i++)
        tq[i] = d[1] * P(T_COL + 1, i) + d[2] * P(T_COL + 2, i) + d[3] * P(T_COL + 3, i) + d[4] * P(T_COL + 4, i)
                + d[5] * P(T_COL + 5, i);
    const lanes_t qq = d[1] * tq[1] + d[2] * tq[2] + d[3] * tq[3] + d[4] * tq[4] + d[5] * tq[5];
    const lanes_t tension = load * (1.0 + axial * qq);
    /* the energy gradient beyond the linear part: K m + sum_c (K e)_c dm_c/dD (+ the load form) */
    lanes_t gr[6];
    gr[0] = k[0] + load * (qq * P(K_ROW0, 0));
    for (int i = 1; i < 6; i++)
        gr[i] = k[i] + load * (qq * P(K_ROW0, i) + load * tq[i]);
    if (symmetric) {  /* each term q d_a d_b gives f_c q d_b to a and f_c q d_a to b */
        gr[1] += fl[2] * q[2] * d[3] + fl[3] * q[4] * d[2] + fl[3] * q[5] * d[4] + fl[4] * q[8] * d[3];
        gr[2] += fl[1] * q[0] * d[3] + fl[3] * q[4] * d[1] + fl[3] * q[6] * d[5] + fl[5] * q[10] * d[3];
        gr[3] += (fl[1] * q[0] * d[2] + fl[1] * q[1] * d[4] + fl[2] * q[2] * d[1] + fl[2] * q[3] * d[5]
                  + fl[4] * q[8] * d[1] + fl[4] * q[9] * d[5] + fl[5] * q[10] * d[2] + fl[5] * q[11] * d[4]);
        gr[4] += fl[1] * q[1] * d[3] + fl[3] * q[5] * d[1] + fl[3] * q[7] * d[5] + fl[5] * q[11] * d[3];
        gr[5] += fl[2] * q[3] * d[3] + fl[3] * q[6] * d[2] + fl[3] * q[7] * d[4] + fl[4] * q[9] * d[3];
    } else {
        for (long t = 0; t < n_terms; t++) {
            const long ia = defect_index[3 * t + 1], ib = defect_index[3 * t + 2];
            const lanes_t wt = fl[defect_index[3 * t]] * q[t];
            gr[ia] += wt * d[ib];
            gr[ib] += wt * d[ia];
        }
    }
    const lanes_t two_t = 2.0 * tension;
    lanes_t v[6];
    for (int i = 0; i < 6; i++)
        v[i] = two_t * s[i] + gr[i];
    for (int a = 0; a < 6; a++)
        f[a] += lane_sum(v[0] * P(J_ROW, a) + v[1] * P(J_ROW + 1, a) + v[2] * P(J_ROW + 2, a)
                         + v[3] * P(J_ROW + 3, a) + v[4] * P(J_ROW + 4, a) + v[5] * P(J_ROW + 5, a)
                         + (e0 * P(W_COL, a) + e1 * P(W_COL + 1, a) + e2 * P(W_COL + 2, a)));
    /* the chain force F (tension along the axis, lateral K e) works through the second-order
       displacement of B: d ext / d theta^T F = 1/2 (p (theta.F) + (theta.p) F - 2 theta (p.F)) */
    const lanes_t g0 = P(R_ROW, 0) * tension + P(R_ROW, 1) * fl[1] + P(R_ROW, 2) * fl[2];
    const lanes_t g1 = P(R_ROW + 1, 0) * tension + P(R_ROW + 1, 1) * fl[1] + P(R_ROW + 1, 2) * fl[2];
    const lanes_t g2 = P(R_ROW + 2, 0) * tension + P(R_ROW + 2, 1) * fl[1] + P(R_ROW + 2, 2) * fl[2];
    const lanes_t tf = t0 * g0 + t1 * g1 + t2 * g2;
    const lanes_t pf = pb0 * g0 + pb1 * g1 + pb2 * g2;
    f[3] += lane_sum(0.5 * (pb0 * tf + tp * g0 - 2.0 * t0 * pf));
    f[4] += lane_sum(0.5 * (pb1 * tf + tp * g1 - 2.0 * t1 * pf));
    f[5] += lane_sum(0.5 * (pb2 * tf + tp * g2 - 2.0 * t2 * pf));
    for (int j = 0; j < 6; j++) {
        r[j] = -rr[j];
        u[j] = uj[j];
        n[j] = tension[j];
    }
    for (int a = 0; a < 6; a++)
        force[a] = f[a];
    force[6] = force[7] = 0.0;
}

/* ``_numba_consistent._equilibrium`` with the map above: the pose x (6) solved in place to ``tol``
   at fixed offsets c by Broyden's steps, the same steps, tests and updates in the same order as
   the numba copy (see its docstring); the command is row p of ``inputs`` (n_p, 3). A candidate's
   read-only arguments (the kernel's own arguments) come in ``context``, int64 slots
   (``consistent_native.CONTEXT``) written once per candidate: each array argument of an inlined
   numba call costs a reference count pair, and with the map in C those were ~1/5 of the kernel's
   time (measured); so does an array's ``.ctypes`` at a call, so every array arrives as its address,
   taken once per candidate. ``secant`` (6 x 6, row-major) is kept from call to call, ``work`` (6 x 6) is
   scratch. Returns 4 x (evaluations of the map) + status, the status 0 converged, 1 not converged
   in max_iter, 2 diverged (``_numba_consistent._status`` maps them to point_status' codes). */
enum { CX_CAND, CX_ROWS, CX_LANES, CX_X0, CX_WEIGHT, CX_TERMS, CX_DEFECT, CX_SYMMETRIC, CX_COMPLIANCE, CX_WRENCH,
       CX_GAIN, CX_SIZE };
_Static_assert(sizeof(void *) == sizeof(int64_t), "addresses travel in int64 slots");

CLONES
long flexcal_consistent_equilibrium(intptr_t context_at, intptr_t x_at, intptr_t c_at, intptr_t n_at, intptr_t r_at,
                                    intptr_t u_at, intptr_t force_at, intptr_t work_at, intptr_t secant_at,
                                    intptr_t inputs_at, long p, double tol, long max_iter, double divergence,
                                    long settle)
{
    const int64_t *cx = (const int64_t *)context_at;
    double *x = (double *)x_at, *n = (double *)n_at, *r = (double *)r_at, *u = (double *)u_at;
    double *force = (double *)force_at, *work = (double *)work_at, *secant = (double *)secant_at;
    const double *c = (const double *)c_at, *inputs = (const double *)inputs_at;
    const long cand = cx[CX_CAND], n_rows = cx[CX_ROWS], n_terms = cx[CX_TERMS], symmetric = cx[CX_SYMMETRIC];
    const double *lanes = (const double *)cx[CX_LANES], *x0 = (const double *)cx[CX_X0];
    const double *weight = (const double *)cx[CX_WEIGHT];
    const long *defect_index = (const long *)cx[CX_DEFECT];
    const double *compliance = (const double *)cx[CX_COMPLIANCE], *wrench = (const double *)cx[CX_WRENCH];
    const double *gain = (const double *)cx[CX_GAIN];
    const double *command = inputs + 3 * p;
    double *x_new = work, *f_prev = work + 6, *s_prev = work + 12, *b_y = work + 18, *s_b = work + 24, *rhs = work + 30;
    const double *cc = compliance + 36 * cand, *gg = gain + 36 * cand, *ww = wrench + 6 * cand;
    double previous = INFINITY;
    for (long it = 0; it < max_iter; it++) {
        flexcal_consistent_terms(cand, n_rows, lanes, x, c, command, x0, weight, n_terms, defect_index, symmetric,
                                 r, u, n, force);
        for (int m = 0; m < 6; m++) {  /* F_C + sum_j g_j u_j - f2(x) */
            double acc = ww[m] - force[m];
            for (int j = 0; j < 6; j++)
                acc += gg[6 * m + j] * u[j];
            rhs[m] = acc;
        }
        double change = 0.0;
        for (int k = 0; k < 6; k++) {
            double acc = 0.0;
            for (int m = 0; m < 6; m++)
                acc += cc[6 * k + m] * rhs[m];
            x_new[k] = acc;
            const double step = fabs(acc - x[k]);
            change = step > change ? step : change;  /* Python's max(change, step), NaN as it does */
        }
        double r_max = 0.0;
        for (int j = 0; j < 6; j++)
            r_max = fabs(r[j]) > r_max ? fabs(r[j]) : r_max;
        if (!isfinite(change) || r_max > divergence) {
            for (int k = 0; k < 6; k++)
                x[k] = x_new[k];
            return 4 * (it + 1) + 2;
        }
        if (change <= tol) {
            if (settle) {  /* x moved to Phi(x), ~rho tol from the fixed point, and its terms */
                for (int k = 0; k < 6; k++)
                    x[k] = x_new[k];
                flexcal_consistent_terms(cand, n_rows, lanes, x, c, command, x0, weight, n_terms, defect_index,
                                         symmetric, r, u, n, force);
            }
            return 4 * (it + 1);
        }
        for (int k = 0; k < 6; k++)  /* residual f = Phi(x) - x, kept in x_new */
            x_new[k] -= x[k];
        if (it > 0) {
            if (change > 0.5 * previous) {  /* the secant model did not help: plain fixed-point steps again */
                for (int a = 0; a < 36; a++)
                    secant[a] = (a % 7 == 0) ? 1.0 : 0.0;
            } else {  /* B+ = B - (s + B y) (s^T B) / (s^T B y), y = f - f_prev: then B+ y = -s */
                for (int a = 0; a < 6; a++) {
                    double acc = 0.0, acc2 = 0.0;
                    for (int b = 0; b < 6; b++) {
                        acc += secant[6 * a + b] * (x_new[b] - f_prev[b]);
                        acc2 += s_prev[b] * secant[6 * b + a];
                    }
                    b_y[a] = acc;
                    s_b[a] = acc2;
                }
                double denominator = 0.0, scale = 0.0;
                for (int a = 0; a < 6; a++) {
                    denominator += s_prev[a] * b_y[a];
                    scale += s_prev[a] * s_prev[a];
                }
                if (fabs(denominator) > 1e-3 * scale) {  /* |B y| ~ |s|: a well-posed update */
                    for (int a = 0; a < 6; a++) {
                        const double row = (s_prev[a] + b_y[a]) / denominator;
                        for (int b = 0; b < 6; b++)
                            secant[6 * a + b] -= row * s_b[b];
                    }
                }
            }
        }
        for (int a = 0; a < 6; a++) {
            double acc = 0.0;
            for (int b = 0; b < 6; b++)
                acc += secant[6 * a + b] * x_new[b];
            s_prev[a] = acc;
            f_prev[a] = x_new[a];
        }
        for (int k = 0; k < 6; k++)
            x[k] += s_prev[k];
        previous = change;
    }
    return 4 * max_iter + 1;
}

/* an importable module, so that setuptools builds it and importlib finds it; numba calls the
   function above by its symbol name */
static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_consistent_map", NULL, -1, NULL};

PyMODINIT_FUNC PyInit__consistent_map(void) { return PyModule_Create(&module); }

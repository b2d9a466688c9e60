/* flexcal.model._consistent_map: the consistent model's per-point work with the six chains as
 * vector lanes (docs/model.md 10, "Session 42"; two halves of four since "Session 44").
 *
 * numba does not vectorize across the chains (its LLVM pass that would, SLP, is off: numba PR
 * 8852), so ``_numba_consistent`` runs one chain after another on scalars. Here every product
 * runs on the six chains at once: the lane rows' two halves of four (chains 0-3, 4-5), each one
 * AVX2 register (GCC's vector extensions, see half_t; with target_clones the loader picks
 * AVX-512's, AVX2's or the baseline's instructions at run time). Three functions, each the numba
 * copy's formulas and steps in the same order, which numba's kernel calls by symbol through
 * ``numba.types.ExternalFunction`` (model/consistent_native.py); the numba copies stay as the
 * reference and the fallback where this module is not built (it needs GCC: ``__builtin_shuffle``):
 * - flexcal_consistent_terms: ``_terms``, the map at one pose (the chains' shortening r, axial
 *   inputs u, tensions n and the second-order wrench);
 * - flexcal_consistent_equilibrium: ``_equilibrium``, Broyden's steps to the map's fixed point;
 * - flexcal_consistent_offsets: ``_numba_kernels``' box and play problems of the nut offsets.
 *
 * Layout (model/consistent.py ``lane_rows``): per candidate ``n_rows`` rows of 8 lanes:
 * rows row * WIDTH + col hold ``pack_chains``' entry [chain, row, col] in lane ``chain``
 * (the same row constants as ``_numba_consistent``); then point_b (3 rows), the axial
 * stiffness (1), and for the equilibrium's 6 x 6 products the frame's gains G[:, j] (6 rows) and
 * compliance columns C[:, m] (6 rows) and its wrench F_C (1 row), in lanes 0-5 (there the lanes
 * are the pose's six components); last the lateral defect's coefficients (n_terms rows).
 *
 * The map skips the zero entries of three of the chains' matrices (session 43: 122 -> 87 ns per
 * evaluation): the chain stiffness K on its blocks ux, rx, (uy, rz), (uz, ry) (the eight entries
 * of ``hinge.ENTRY_INDEX``), the transform J with no rotation row seeing the frame's translation,
 * the load form T on the lateral rows and columns (uy, uz, ry, rz). ``consistent.lanes_apply``
 * checks those zeros before this code runs; numba's ``_terms`` keeps the full sums.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>

/* the vector type: four lanes, the width of an AVX2 register. The six chains are two halves of
   four lanes (chains 0-3, 4-5 and two zero lanes), and so are the pose's six components. (Session
   44: as one 64-byte vector, the lanes were one register only with AVX-512; elsewhere GCC kept
   every vector in memory and built each scalar's broadcast there, by narrow stores read back by
   wide loads whose store forwarding fails: on an AVX2 machine the map ran 3.4x slower per
   evaluation than on an AVX-512 one, against 1.7x for numba's scalar code.) */
typedef double half_t __attribute__((vector_size(32)));
typedef double half_u __attribute__((vector_size(32), aligned(8)));  /* numpy's rows: 8-byte aligned */
typedef int64_t half_index __attribute__((vector_size(32)));

enum {
    WIDTH = 8, J_COL = 0, R_ROW = 6, S_COL = 9, K_COL = 15, T_COL = 21, J_ROW = 27, W_COL = 33, GAIN = 36,
    AXIAL_ROW = 37, K_ROW0 = 38, N_PACK = 39,
    POINT = N_PACK * WIDTH, AXIAL = POINT + 3, GAIN_COLUMNS = AXIAL + 1, COMPLIANCE_COLUMNS = GAIN_COLUMNS + 6,
    WRENCH = COMPLIANCE_COLUMNS + 6, DEFECT = WRENCH + 1
};

#if defined(__GNUC__) && defined(__x86_64__) && !defined(__clang__)
#define CLONES __attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
#else
#define CLONES
#endif

/* an 8-lane vector as its two halves [0] (lanes 0-3) and [1] (lanes 4-7) */
static inline double lane_sum(const half_t *a)
{
    return ((a[0][0] + a[0][1]) + (a[0][2] + a[0][3])) + ((a[1][0] + a[1][1]) + (a[1][2] + a[1][3]));
}

/* {a0 + a1, b0 + b1, a2 + a3, b2 + b3} */
static inline half_t pair_sums(half_t a, half_t b)
{
    return __builtin_shuffle(a, b, (half_index){0, 4, 2, 6}) + __builtin_shuffle(a, b, (half_index){1, 5, 3, 7});
}

/* {a0 + a2, a1 + a3, b0 + b2, b1 + b3} */
static inline half_t quad_sums(half_t a, half_t b)
{
    return __builtin_shuffle(a, b, (half_index){0, 1, 4, 5}) + __builtin_shuffle(a, b, (half_index){2, 3, 6, 7});
}

/* out's lane k (halves out[0], out[1]) = the sum of the 8-lane vector a[k]'s lanes (a[k][0] and
   a[k][1] its halves; k < 6, lanes 6, 7 of out zero) in ``lane_sum``'s order: six sums at once by
   three rounds of pairwise shuffles, instead of six sums of one vector each */
static inline void lane_sums6(half_t a[6][2], half_t *out)
{
    const half_t zero = {0};
    half_t s01[2], s23[2], s45[2], t03[2], t47[2];
    for (int h = 0; h < 2; h++) {
        s01[h] = pair_sums(a[0][h], a[1][h]);
        s23[h] = pair_sums(a[2][h], a[3][h]);
        s45[h] = pair_sums(a[4][h], a[5][h]);
        t03[h] = quad_sums(s01[h], s23[h]);
        t47[h] = quad_sums(s45[h], zero);
    }
    out[0] = t03[0] + t03[1];
    out[1] = t47[0] + t47[1];
}

/* one half's share of the map (its four chains as lanes): r, u, n and the chain wrench's six
   components, each summed over the chains by the caller */
struct map_half {
    half_t r, u, n, wrench[6];
};

#define ROW(row) (L[2 * (row)])  /* a lane row's half */
#define P(row, col) ROW((row) * WIDTH + (col))
#define Q(t) ROW(DEFECT + (t))  /* the lateral defect's coefficients */

/* the map at pose x (its halves ``pose``) for half h of one candidate's chains: ``block`` its lane
   rows, ``offset`` the half's lanes of the drives' offsets (``drive_offsets``) */
static inline __attribute__((always_inline)) struct map_half
map_at_half(const double *restrict block, int h, const half_t *pose, half_t offset, int64_t n_terms,
            const int64_t *restrict defect_index, int64_t symmetric)
{
    const half_u *L = (const half_u *)(block + 4 * h);
    const double x[6] = {pose[0][0], pose[0][1], pose[0][2], pose[0][3], pose[1][0], pose[1][1]};
    const double t0 = x[3], t1 = x[4], t2 = x[5];
    const double tt = t0 * t0 + t1 * t1 + t2 * t2;
    struct map_half out;  /* out.wrench[a]: component a of each chain's second-order wrench */
    half_t *chain_wrench = out.wrench;
    const half_t pb0 = ROW(POINT), pb1 = ROW(POINT + 1), pb2 = ROW(POINT + 2);
    const half_t tp = t0 * pb0 + t1 * pb1 + t2 * pb2;
    const half_t e0 = 0.5 * (t0 * tp - pb0 * tt);  /* ext = 1/2 theta x (theta x p_j) */
    const half_t e1 = 0.5 * (t1 * tp - pb1 * tt);
    const half_t e2 = 0.5 * (t2 * tp - pb2 * tt);
    half_t ec[3], d[6], s[6];
    for (int k = 0; k < 3; k++)
        ec[k] = e0 * P(R_ROW, k) + e1 * P(R_ROW + 1, k) + e2 * P(R_ROW + 2, k);
    for (int k = 0; k < 3; k++)
        d[k] = x[0] * P(J_COL, k) + x[1] * P(J_COL + 1, k) + x[2] * P(J_COL + 2, k) + x[3] * P(J_COL + 3, k)
               + x[4] * P(J_COL + 4, k) + x[5] * P(J_COL + 5, k) + ec[k];
    for (int k = 3; k < 6; k++)  /* J's rotation rows see the frame's rotation only */
        d[k] = x[3] * P(J_COL + 3, k) + x[4] * P(J_COL + 4, k) + x[5] * P(J_COL + 5, k);
    for (int k = 0; k < 6; k++)
        s[k] = d[0] * P(S_COL, k) + d[1] * P(S_COL + 1, k) + d[2] * P(S_COL + 2, k) + d[3] * P(S_COL + 3, k)
               + d[4] * P(S_COL + 4, k) + d[5] * P(S_COL + 5, k);
    const half_t rr = d[0] * s[0] + d[1] * s[1] + d[2] * s[2] + d[3] * s[3] + d[4] * s[4] + d[5] * s[5];
    const half_t uj = -rr + offset;

    /* the lateral compatibility defect m_c = sum_t q_t d_a d_b (c = y..rz) */
    half_t m[6];
    if (symmetric) {  /* _numba_consistent.SYMMETRIC_DEFECT's terms in its order */
        m[1] = Q(0) * d[2] * d[3] + Q(1) * d[3] * d[4];
        m[2] = Q(2) * d[1] * d[3] + Q(3) * d[3] * d[5];
        m[3] = Q(4) * d[1] * d[2] + Q(5) * d[1] * d[4] + Q(6) * d[2] * d[5] + Q(7) * d[4] * d[5];
        m[4] = Q(8) * d[1] * d[3] + Q(9) * d[3] * d[5];
        m[5] = Q(10) * d[2] * d[3] + Q(11) * d[3] * d[4];
    } else {
        for (int i = 1; i < 6; i++)
            m[i] = (half_t){0};
        for (int64_t t = 0; t < n_terms; t++)
            m[defect_index[3 * t]] += Q(t) * d[defect_index[3 * t + 1]] * d[defect_index[3 * t + 2]];
    }
    /* K m, and the lateral chain force (K e)_c = K m - K[:, 0] u + K D (c = y..rz), on K's blocks:
       ux and rx alone, (uy, rz) and (uz, ry) (``_numba_consistent``'s sums without their zero terms) */
    half_t k[6], fl[6];
    k[0] = (half_t){0};
    k[1] = m[1] * P(K_COL + 1, 1) + m[5] * P(K_COL + 5, 1);
    k[2] = m[2] * P(K_COL + 2, 2) + m[4] * P(K_COL + 4, 2);
    k[3] = m[3] * P(K_COL + 3, 3);
    k[4] = m[2] * P(K_COL + 2, 4) + m[4] * P(K_COL + 4, 4);
    k[5] = m[1] * P(K_COL + 1, 5) + m[5] * P(K_COL + 5, 5);
    fl[0] = (half_t){0};  /* (the tension carries the axial force) */
    fl[1] = k[1] + (d[1] * P(K_COL + 1, 1) + d[5] * P(K_COL + 5, 1));
    fl[2] = k[2] + (d[2] * P(K_COL + 2, 2) + d[4] * P(K_COL + 4, 2));
    fl[3] = k[3] + d[3] * P(K_COL + 3, 3);
    fl[4] = k[4] + (d[2] * P(K_COL + 2, 4) + d[4] * P(K_COL + 4, 4));
    fl[5] = k[5] + (d[1] * P(K_COL + 1, 5) + d[5] * P(K_COL + 5, 5));
    const half_t axial = ROW(AXIAL);
    half_t load = -axial * uj;
    load += P(GAIN, 0) * x[0] + P(GAIN, 1) * x[1] + P(GAIN, 2) * x[2] + P(GAIN, 3) * x[3] + P(GAIN, 4) * x[4]
            + P(GAIN, 5) * x[5];
    load += P(AXIAL_ROW, 0) * ec[0];
    /* the chain's own P-delta inside: tension N (1 + k q), shortening D^T (S + N T) D; T lives on the
       lateral rows and columns (uy, uz, ry, rz) */
    half_t tq[6];
    tq[0] = tq[3] = (half_t){0};
    for (int i = 1; i < 6; i++)
        if (i != 3)
            tq[i] = d[1] * P(T_COL + 1, i) + d[2] * P(T_COL + 2, i) + d[4] * P(T_COL + 4, i)
                    + d[5] * P(T_COL + 5, i);
    const half_t qq = d[1] * tq[1] + d[2] * tq[2] + d[4] * tq[4] + d[5] * tq[5];
    const half_t tension = load * (1.0 + axial * qq);
    /* the energy gradient beyond the linear part: K m + sum_c (K e)_c dm_c/dD (+ the load form) */
    half_t gr[6];
    gr[0] = load * (qq * P(K_ROW0, 0));
    for (int i = 1; i < 6; i++)
        gr[i] = k[i] + load * (load * tq[i]);
    if (symmetric) {  /* each term q d_a d_b gives f_c q d_b to a and f_c q d_a to b */
        gr[1] += fl[2] * Q(2) * d[3] + fl[3] * Q(4) * d[2] + fl[3] * Q(5) * d[4] + fl[4] * Q(8) * d[3];
        gr[2] += fl[1] * Q(0) * d[3] + fl[3] * Q(4) * d[1] + fl[3] * Q(6) * d[5] + fl[5] * Q(10) * d[3];
        gr[3] += (fl[1] * Q(0) * d[2] + fl[1] * Q(1) * d[4] + fl[2] * Q(2) * d[1] + fl[2] * Q(3) * d[5]
                  + fl[4] * Q(8) * d[1] + fl[4] * Q(9) * d[5] + fl[5] * Q(10) * d[2] + fl[5] * Q(11) * d[4]);
        gr[4] += fl[1] * Q(1) * d[3] + fl[3] * Q(5) * d[1] + fl[3] * Q(7) * d[5] + fl[5] * Q(11) * d[3];
        gr[5] += fl[2] * Q(3) * d[3] + fl[3] * Q(6) * d[2] + fl[3] * Q(7) * d[4] + fl[4] * Q(9) * d[3];
    } else {
        for (int64_t t = 0; t < n_terms; t++) {
            const int64_t ia = defect_index[3 * t + 1], ib = defect_index[3 * t + 2];
            const half_t wt = fl[defect_index[3 * t]] * Q(t);
            gr[ia] += wt * d[ib];
            gr[ib] += wt * d[ia];
        }
    }
    const half_t two_t = 2.0 * tension;
    half_t v[6];
    for (int i = 0; i < 6; i++)
        v[i] = two_t * s[i] + gr[i];
    for (int a = 0; a < 3; a++)  /* J^T v: the frame's force sees the chain's force only */
        chain_wrench[a] = v[0] * P(J_ROW, a) + v[1] * P(J_ROW + 1, a) + v[2] * P(J_ROW + 2, a)
                          + (e0 * P(W_COL, a) + e1 * P(W_COL + 1, a) + e2 * P(W_COL + 2, a));
    for (int a = 3; a < 6; a++)
        chain_wrench[a] = v[0] * P(J_ROW, a) + v[1] * P(J_ROW + 1, a) + v[2] * P(J_ROW + 2, a)
                          + v[3] * P(J_ROW + 3, a) + v[4] * P(J_ROW + 4, a) + v[5] * P(J_ROW + 5, a)
                          + (e0 * P(W_COL, a) + e1 * P(W_COL + 1, a) + e2 * P(W_COL + 2, a));
    /* the chain force F (tension along the axis, lateral K e) works through the second-order
       displacement of B: d ext / d theta^T F = 1/2 (p (theta.F) + (theta.p) F - 2 theta (p.F)) */
    const half_t g0 = P(R_ROW, 0) * tension + P(R_ROW, 1) * fl[1] + P(R_ROW, 2) * fl[2];
    const half_t g1 = P(R_ROW + 1, 0) * tension + P(R_ROW + 1, 1) * fl[1] + P(R_ROW + 1, 2) * fl[2];
    const half_t g2 = P(R_ROW + 2, 0) * tension + P(R_ROW + 2, 1) * fl[1] + P(R_ROW + 2, 2) * fl[2];
    const half_t tf = t0 * g0 + t1 * g1 + t2 * g2;
    const half_t pf = pb0 * g0 + pb1 * g1 + pb2 * g2;
    chain_wrench[3] += 0.5 * (pb0 * tf + tp * g0 - 2.0 * t0 * pf);
    chain_wrench[4] += 0.5 * (pb1 * tf + tp * g1 - 2.0 * t1 * pf);
    chain_wrench[5] += 0.5 * (pb2 * tf + tp * g2 - 2.0 * t2 * pf);
    out.r = -rr;
    out.u = uj;
    out.n = tension;
    return out;
}

/* the map's outputs, 8-lane vectors as their halves: the chains' shortening r, axial inputs u and
   tensions n (the chains as lanes), and the second-order wrench (its six components as lanes) */
struct map_out {
    half_t r[2], u[2], n[2], force[2];
};

/* the drives' offsets command + x0 + c in the chains' lanes 3-5, as halves */
static inline void drive_offsets(const double *command, const double *x0c, const double *c, half_t *offset)
{
    offset[0] = (half_t){0.0, 0.0, 0.0, command[0] + x0c[0] + c[0]};
    offset[1] = (half_t){command[1] + x0c[1] + c[1], command[2] + x0c[2] + c[2], 0.0, 0.0};
}

/* the map at pose x (its halves) for one candidate: ``block`` its lane rows, ``offset`` its drives'
   offsets (``drive_offsets``), w its weight (6) */
static inline __attribute__((always_inline)) struct map_out
map_at(const double *restrict block, const half_t *x, const half_t *offset, const double *restrict w, int64_t n_terms,
       const int64_t *restrict defect_index, int64_t symmetric)
{
    const double t0 = x[0][3], t1 = x[1][0], t2 = x[1][1];
    /* the weight W at the centre of gravity r turns with the frame: -d ext_r / d theta^T W */
    const double tw = t0 * w[0] + t1 * w[1] + t2 * w[2];
    const double tr = t0 * w[3] + t1 * w[4] + t2 * w[5];
    const double rw = w[3] * w[0] + w[4] * w[1] + w[5] * w[2];
    const half_t turn_0 = {0.0, 0.0, 0.0, -0.5 * (w[3] * tw + tr * w[0] - 2.0 * t0 * rw)};
    const half_t turn_1 = {-0.5 * (w[4] * tw + tr * w[1] - 2.0 * t1 * rw),
                           -0.5 * (w[5] * tw + tr * w[2] - 2.0 * t2 * rw), 0.0, 0.0};
    half_t chain_wrench[6][2];
    struct map_out out;
    for (int h = 0; h < 2; h++) {
        const struct map_half half = map_at_half(block, h, x, offset[h], n_terms, defect_index, symmetric);
        out.r[h] = half.r;
        out.u[h] = half.u;
        out.n[h] = half.n;
        for (int a = 0; a < 6; a++)
            chain_wrench[a][h] = half.wrench[a];
    }
    lane_sums6(chain_wrench, out.force);
    out.force[0] = turn_0 + out.force[0];
    out.force[1] = turn_1 + out.force[1];
    return out;
}

/* lane k of an 8-lane vector's halves v */
#define LANE(v, k) ((v)[(k) / 4][(k) % 4])

static inline void load_halves(const double *v, half_t *out)  /* 6 doubles, lanes 6, 7 zero */
{
    out[0] = (half_t){v[0], v[1], v[2], v[3]};
    out[1] = (half_t){v[4], v[5], 0.0, 0.0};
}

/* the map at pose x for candidate ``cand`` of the lane rows (n_c, n_rows, 8): r, u, n (6) and force
   (8, its entries 6 and 7 zero) as ``_numba_consistent._terms`` gives them */
CLONES
void flexcal_consistent_terms(int64_t cand, int64_t n_rows, const double *lanes, const double *x, const double *c,
                              const double *command, const double *x0, const double *weight, int64_t n_terms,
                              const int64_t *defect_index, int64_t symmetric, double *r, double *u, double *n,
                              double *force)
{
    half_t pose[2], offset[2];
    load_halves(x, pose);
    drive_offsets(command, x0 + 3 * cand, c, offset);
    const struct map_out out = map_at(lanes + cand * n_rows * WIDTH, pose, offset, weight + 6 * cand, n_terms,
                                      defect_index, symmetric);
    for (int k = 0; k < 6; k++) {
        r[k] = LANE(out.r, k);
        u[k] = LANE(out.u, k);
        n[k] = LANE(out.n, k);
        force[k] = LANE(out.force, k);
    }
    force[6] = force[7] = 0.0;
}

/* ``_numba_consistent._equilibrium`` with the map above: the pose x (6) solved in place to ``tol``
   at fixed offsets c by Broyden's steps, the same steps, tests and updates in the same order as
   the numba copy (see its docstring); the command is row p of ``inputs`` (n_p, 3). A candidate's
   read-only arguments come in ``context``, int64 slots (``consistent_native.CONTEXT``) written once
   per candidate, and every other array as its address taken once per candidate: an array argument
   of an inlined numba call, or its ``.ctypes`` at a call, costs a reference count pair, ~15 % of
   the kernel's time once the map ran in C (measured). ``secant`` (6, 8) holds B's six columns
   (lanes 6, 7 zero), kept from call to call. Returns 4 x (evaluations of the map) + status, the
   status 0 converged, 1 not converged in max_iter, 2 diverged (``_numba_consistent._status`` maps
   them to point_status' codes). */
/* CX_STRIDE: the lane rows from one candidate's block to the next in CX_LANES (0 where it holds the
   one candidate's block, as the kernel passes it) */
enum { CX_CAND, CX_STRIDE, CX_LANES, CX_X0, CX_WEIGHT, CX_TERMS, CX_DEFECT, CX_SYMMETRIC, CX_SIZE };
_Static_assert(sizeof(void *) == sizeof(int64_t), "addresses travel in int64 slots");

static inline double max_abs6(const half_t *v)
{
    double worst = 0.0;
    for (int k = 0; k < 6; k++) {
        const double a = fabs(LANE(v, k));
        worst = a > worst ? a : worst;  /* Python's max(worst, a), NaN as the numba copy */
    }
    return worst;
}

CLONES
int64_t flexcal_consistent_equilibrium(intptr_t context_at, intptr_t x_at, intptr_t c_at, intptr_t n_at,
                                       intptr_t r_at, intptr_t u_at, intptr_t force_at, intptr_t secant_at,
                                       intptr_t inputs_at, int64_t p, double tol, int64_t max_iter, double divergence,
                                       int64_t settle)
{
    const int64_t *cx = (const int64_t *)context_at;
    const int64_t cand = cx[CX_CAND], n_terms = cx[CX_TERMS], symmetric = cx[CX_SYMMETRIC];
    const double *block = (const double *)cx[CX_LANES] + cand * cx[CX_STRIDE] * WIDTH;
    const double *x0c = (const double *)cx[CX_X0] + 3 * cand, *w = (const double *)cx[CX_WEIGHT] + 6 * cand;
    const int64_t *defect_index = (const int64_t *)cx[CX_DEFECT];
    const double *command = (const double *)inputs_at + 3 * p, *c = (const double *)c_at;
    const half_u *L = (const half_u *)block;
    /* the 6 x 6 products on the pose's six components as lanes: G u = sum_j u_j G[:, j], and so
       on; B as its six columns, ``secant`` (6, 8) holding them (lanes 6, 7 zero); every 8-lane
       vector as its two halves */
    const half_u *gain = L + 2 * GAIN_COLUMNS, *compliance = L + 2 * COMPLIANCE_COLUMNS, *wrench = L + 2 * WRENCH;
    half_u *secant = (half_u *)secant_at;
    half_t B[6][2], x[2], offset[2], f_prev[2] = {{0}}, s_prev[2] = {{0}};
    load_halves((const double *)x_at, x);
    drive_offsets(command, x0c, c, offset);
    for (int b = 0; b < 6; b++)
        for (int h = 0; h < 2; h++)
            B[b][h] = secant[2 * b + h];
    struct map_out out = {{{0}}};
    double previous = INFINITY;
    int64_t packed = 4 * max_iter + 1;
    for (int64_t it = 0; it < max_iter; it++) {
        out = map_at(block, x, offset, w, n_terms, defect_index, symmetric);
        half_t rhs[2], x_new[2] = {{0}}, residual[2];
        for (int h = 0; h < 2; h++)
            rhs[h] = wrench[h] - out.force[h];  /* F_C + sum_j g_j u_j - f2(x) */
        for (int j = 0; j < 6; j++)
            for (int h = 0; h < 2; h++)
                rhs[h] += LANE(out.u, j) * gain[2 * j + h];
        for (int m = 0; m < 6; m++)
            for (int h = 0; h < 2; h++)
                x_new[h] += LANE(rhs, m) * compliance[2 * m + h];
        for (int h = 0; h < 2; h++)
            residual[h] = x_new[h] - x[h];  /* f = Phi(x) - x */
        const double change = max_abs6(residual);
        const double r_max = max_abs6(out.r);
        if (!isfinite(change) || r_max > divergence) {
            x[0] = x_new[0], x[1] = x_new[1];
            packed = 4 * (it + 1) + 2;
            break;
        }
        if (change <= tol) {
            if (settle) {  /* x moved to Phi(x), ~rho tol from the fixed point, and its terms */
                x[0] = x_new[0], x[1] = x_new[1];
                out = map_at(block, x, offset, w, n_terms, defect_index, symmetric);
            }
            packed = 4 * (it + 1);
            break;
        }
        if (it > 0) {
            if (change > 0.5 * previous) {  /* the secant model did not help: plain fixed-point steps again */
                for (int b = 0; b < 6; b++) {
                    B[b][0] = B[b][1] = (half_t){0};
                    LANE(B[b], b) = 1.0;
                }
            } else {  /* B+ = B - (s + B y) (s^T B) / (s^T B y), y = f - f_prev: then B+ y = -s */
                half_t y[2], b_y[2] = {{0}}, s_bb[6][2], s_b[2], s_by[2], s_s[2];
                for (int h = 0; h < 2; h++)
                    y[h] = residual[h] - f_prev[h];
                for (int b = 0; b < 6; b++)
                    for (int h = 0; h < 2; h++) {
                        b_y[h] += LANE(y, b) * B[b][h];
                        s_bb[b][h] = s_prev[h] * B[b][h];
                    }
                lane_sums6(s_bb, s_b);
                for (int h = 0; h < 2; h++) {
                    s_by[h] = s_prev[h] * b_y[h];
                    s_s[h] = s_prev[h] * s_prev[h];
                }
                const double denominator = lane_sum(s_by), scale = lane_sum(s_s);
                if (fabs(denominator) > 1e-3 * scale) {  /* |B y| ~ |s|: a well-posed update */
                    half_t row[2];
                    for (int h = 0; h < 2; h++)
                        row[h] = (s_prev[h] + b_y[h]) / denominator;
                    for (int b = 0; b < 6; b++)
                        for (int h = 0; h < 2; h++)
                            B[b][h] -= row[h] * LANE(s_b, b);
                }
            }
        }
        s_prev[0] = s_prev[1] = (half_t){0};
        for (int b = 0; b < 6; b++)
            for (int h = 0; h < 2; h++)
                s_prev[h] += LANE(residual, b) * B[b][h];
        for (int h = 0; h < 2; h++) {
            f_prev[h] = residual[h];
            x[h] += s_prev[h];
        }
        previous = change;
    }
    double *x_out = (double *)x_at, *r = (double *)r_at, *u = (double *)u_at, *n = (double *)n_at;
    double *force = (double *)force_at;
    for (int k = 0; k < 6; k++) {
        x_out[k] = LANE(x, k);
        r[k] = LANE(out.r, k);
        u[k] = LANE(out.u, k);
        n[k] = LANE(out.n, k);
        force[k] = LANE(out.force, k);
    }
    for (int b = 0; b < 6; b++)
        for (int h = 0; h < 2; h++)
            secant[2 * b + h] = B[b][h];
    return packed;
}

/* ``_numba_kernels``' box and play problems of the nut offsets (docs/model.md 6, 9), the same
   steps in the same order: face_values, face_slack, enumerate_box, solve_box, solve_play. The
   consistent kernel calls them once per Newton step on the offsets; as inlined numba calls their
   fifteen array arguments cost ~35 reference count pairs per posture, ~15 % of the kernel's time
   with the map in C (measured). b is 3 x 3 row-major, status 0 lower / 1 free / 2 upper. */
static int face_values(const int64_t *status, const double *a, const double *b, const double *lo, const double *hi,
                       double *out)
{
    for (int i = 0; i < 3; i++)
        out[i] = status[i] == 0 ? lo[i] : (status[i] == 2 ? hi[i] : 0.0);
    const double r0 = a[0] + b[1] * out[1] + b[2] * out[2];
    const double r1 = a[1] + b[3] * out[0] + b[5] * out[2];
    const double r2 = a[2] + b[6] * out[0] + b[7] * out[1];
    const int f0 = status[0] == 1, f1 = status[1] == 1, f2 = status[2] == 1;
    const int n_free = f0 + f1 + f2;
    if (n_free == 0)
        return 1;
    if (n_free == 1) {  /* B_ii = 0: the free chain's equation is explicit */
        if (f0)
            out[0] = r0;
        else if (f1)
            out[1] = r1;
        else
            out[2] = r2;
        return 1;
    }
    /* identity-padded 3x3: rows/columns of clamped chains are the unit vectors */
    const double m01 = (f0 && f1) ? -b[1] : 0.0, m02 = (f0 && f2) ? -b[2] : 0.0;
    const double m10 = (f1 && f0) ? -b[3] : 0.0, m12 = (f1 && f2) ? -b[5] : 0.0;
    const double m20 = (f2 && f0) ? -b[6] : 0.0, m21 = (f2 && f1) ? -b[7] : 0.0;
    const double s0 = f0 ? r0 : 0.0, s1 = f1 ? r1 : 0.0, s2 = f2 ? r2 : 0.0;
    const double det = (1.0 - m12 * m21) - m01 * (m10 - m12 * m20) + m02 * (m10 * m21 - m20);
    if (det == 0.0)
        return 0;
    const double x0 = (s0 * (1.0 - m12 * m21) - m01 * (s1 - m12 * s2) + m02 * (s1 * m21 - s2)) / det;
    const double x1 = ((s1 - m12 * s2) - s0 * (m10 - m12 * m20) + m02 * (m10 * s2 - m20 * s1)) / det;
    const double x2 = ((s2 - m21 * s1) - m01 * (m10 * s2 - s1 * m20) + s0 * (m10 * m21 - m20)) / det;
    if (f0)
        out[0] = x0;
    if (f1)
        out[1] = x1;
    if (f2)
        out[2] = x2;
    return 1;
}

static double face_slack(const int64_t *status, const double *c, const double *a, const double *b, const double *lo,
                         const double *hi)
{
    double worst = -INFINITY;
    for (int i = 0; i < 3; i++) {
        double v;
        if (status[i] == 1) {
            v = (lo[i] - c[i]) > (c[i] - hi[i]) ? (lo[i] - c[i]) : (c[i] - hi[i]);
        } else {
            double z = a[i];
            for (int j = 0; j < 3; j++)
                z += b[3 * i + j] * c[j];
            v = status[i] == 0 ? z - lo[i] : hi[i] - z;
        }
        worst = v > worst ? v : worst;
    }
    return worst;
}

/* Python's min(max(v, lo), hi), as the numba copy: the same value for equal arguments */
static inline double clip(double v, double lo, double hi)
{
    const double m = lo > v ? lo : v;
    return hi < m ? hi : m;
}

static int enumerate_box(const double *a, const double *b, const double *lo, const double *hi, int64_t *status,
                         double tol, double *c)
{
    double best = INFINITY, trial[3];
    int64_t best_face = -1, face[3];
    for (int64_t f = 0; f < 27; f++) {  /* the faces in _FACES' order: (i, j, k) over {0, 1, 2}^3 */
        face[0] = f / 9, face[1] = (f / 3) % 3, face[2] = f % 3;
        if (!face_values(face, a, b, lo, hi, trial))
            continue;
        const double slack = face_slack(face, trial, a, b, lo, hi);
        if (slack < best) {
            best = slack;
            best_face = f;
            if (slack <= tol)
                break;
        }
    }
    if (best_face < 0 || best > 1e-9 + tol)
        return 0;
    status[0] = best_face / 9, status[1] = (best_face / 3) % 3, status[2] = best_face % 3;
    face_values(status, a, b, lo, hi, c);
    for (int i = 0; i < 3; i++)
        c[i] = clip(c[i], lo[i], hi[i]);
    return 1;
}

static int solve_box(const double *a, const double *b, const double *lo, const double *hi, int64_t *status, double tol,
                     double *c)
{
    for (int sweep = 0; sweep < 8; sweep++) {
        if (!face_values(status, a, b, lo, hi, c))
            break;
        int changed = 0;
        for (int i = 0; i < 3; i++) {
            if (status[i] == 1) {
                if (c[i] < lo[i] - tol) {
                    status[i] = 0;
                    changed = 1;
                } else if (c[i] > hi[i] + tol) {
                    status[i] = 2;
                    changed = 1;
                }
            } else {
                const double z = a[i] + b[3 * i] * c[0] + b[3 * i + 1] * c[1] + b[3 * i + 2] * c[2];
                if (status[i] == 0 && z > lo[i] + tol) {
                    status[i] = z >= hi[i] ? 2 : 1;
                    changed = 1;
                } else if (status[i] == 2 && z < hi[i] - tol) {
                    status[i] = z <= lo[i] ? 0 : 1;
                    changed = 1;
                }
            }
        }
        if (!changed) {
            for (int i = 0; i < 3; i++)
                c[i] = clip(c[i], lo[i], hi[i]);
            return 1;
        }
    }
    return enumerate_box(a, b, lo, hi, status, tol, c);
}

/* C = clip(play(C_prev, a + B C, band), lo, hi) in place into c, or (play 0) the box problem
   C = clip(a + B C, lo, hi); status (and the play's sides ``side``) updated; 1 solved, 0 failed.
   Every array arrives as its address (see flexcal_consistent_equilibrium). */
CLONES
int64_t flexcal_consistent_offsets(intptr_t a_at, intptr_t b_at, intptr_t lo_at, intptr_t hi_at,
                                   intptr_t c_prev_at, intptr_t band_at, intptr_t side_at, intptr_t status_at,
                                   double tol, intptr_t c_at, int64_t play, int64_t fresh)
{
    const double *a = (const double *)a_at, *b = (const double *)b_at, *lo = (const double *)lo_at;
    const double *hi = (const double *)hi_at, *c_prev = (const double *)c_prev_at, *band = (const double *)band_at;
    double *side = (double *)side_at, *c = (double *)c_at;
    int64_t *status = (int64_t *)status_at;
    if (!play)
        return solve_box(a, b, lo, hi, status, tol, c);
    double lo2[3], hi2[3], a2[3];
    if (fresh) {  /* side guess: where the target at the previous offsets lies */
        for (int i = 0; i < 3; i++) {
            const double t = a[i] + b[3 * i] * c_prev[0] + b[3 * i + 1] * c_prev[1] + b[3 * i + 2] * c_prev[2];
            side[i] = t >= c_prev[i] ? 1.0 : -1.0;
        }
    }
    for (int attempt = 0; attempt < 8; attempt++) {
        for (int i = 0; i < 3; i++) {
            if (side[i] > 0) {
                lo2[i] = c_prev[i] > lo[i] ? c_prev[i] : lo[i];
                hi2[i] = hi[i];
                a2[i] = a[i] - band[i];
            } else {
                lo2[i] = lo[i];
                hi2[i] = c_prev[i] < hi[i] ? c_prev[i] : hi[i];
                a2[i] = a[i] + band[i];
            }
            if (lo2[i] > hi2[i])
                lo2[i] = hi2[i];
        }
        if (!solve_box(a2, b, lo2, hi2, status, tol, c))
            return 0;
        int changed = 0;
        for (int i = 0; i < 3; i++) {
            const double t = a[i] + b[3 * i] * c[0] + b[3 * i + 1] * c[1] + b[3 * i + 2] * c[2];
            if (side[i] > 0 && t < c_prev[i] - band[i] - tol) {
                side[i] = -1.0;
                changed = 1;
            } else if (side[i] < 0 && t > c_prev[i] + band[i] + tol) {
                side[i] = 1.0;
                changed = 1;
            }
        }
        if (!changed)
            return 1;
    }
    return 0;
}

/* an importable module, so that setuptools builds it and importlib finds it; numba calls the
   function above by its symbol name */
static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_consistent_map", NULL, -1, NULL};

PyMODINIT_FUNC PyInit__consistent_map(void) { return PyModule_Create(&module); }

/* vsweep.c: the horizon sweep of vsweep.h (what it proves, and when it casts instead).
 *
 * Cone coordinates. Each cone is swept as if it were the east one: a sample (U, V) of
 * the cone is grid sample i = ui U + vi V, j = uj U + vj V (west: U = -i; north: U = j,
 * V = i; south: U = -j), the eye is (eu, ev), u = U - eu > 0 is the distance along the
 * sweep and m = (V - ev) / u, |m| <= 1, the ray's direction. Cells are the grid's; a
 * triangle cell's diagonal (a + b = 1 in the grid's frame) is the anti-diagonal
 * (U+1, V)-(U, V+1) in the east and north cones and the main one in the other two.
 *
 * The envelope F(m) is a list of pieces, each a part of one projected edge: value
 * qr + s (m - mr) from its start m to the next piece's start, and a slack: the piece is
 * an upper bound of the surface on the rays it covers, and value - slack is reached by a
 * real surface point (slack 0 for real edges, |twist| / 4 / u for a bilinear cell's
 * upper diagonal, |qa - qb| for an edge too narrow in m to keep its slope, which is then
 * kept flat at its top). After the targets of column U are decided against F, the edges
 * of column U and of the strip between columns U-1 and U (rows, diagonals) are added:
 * each is first tested against F (most far terrain is under the horizon and is dropped
 * there), the others are gathered in G (in m order, so each insertion touches G's tail)
 * and G is merged into F in one pass. Holes: an edge counts when a cell it bounds has no
 * void corner (the tracer skips hole cells).
 *
 * A target T = (U, V) is decided by
 *   hi = max(F(m_T), NB, last-cell diagonal, with a target height its own ground),
 *   lo = max(F(m_T) - slack, last-cell diagonal - slack),
 * visible if q_T > hi + eps, hidden if q_T < lo - eps, else (band_lo) hidden if a real
 * point of the bilinear strip whose upper diagonal F's piece is lies above the segment on
 * its ray by eps, else cast. The edges that end at T
 * are not in F yet (F holds the strips up to column U-1), and the only edge the segment
 * crosses in its last strip is the diagonal of the cell it arrives through when that
 * diagonal does not end at T. NB bounds the part of every segment between the eye and
 * the first column U0 at least a quarter cell away: per cell, by its highest corner over
 * its nearest distance, or for the cells around the eye by the slope bound
 * z <= ground + G u, so q <= G - height / u (the linear surface, whose height under the
 * eye depends on the ray, gets no such bound). Targets in columns up to U0 + 1 are cast.
 *
 * The column pass (from u = VS_PASS_U on). One walk along F per column (col_pass) gives
 * each target its piece of F and F's minimum and maximum over each interval [m_V, m_V+1]
 * between the column's samples; a column edge under that minimum is left out, the others
 * become pieces straight from the column's arrays (they meet end to end in m order).
 * A strip edge ends on the column and spans one or two of its intervals: it is left out
 * when under the lower bound of F there once the column is in (lcol) or under the
 * column's polyline (facing slopes), else tested exactly by add_seg (into G); then one
 * pass (col_merge) builds the new F from the old one interval by interval: F's own pieces
 * where the column's edge does not count, the edge alone where it is above F's maximum,
 * the two compared elsewhere, and G's pieces merged where there are any (merge_span).
 * The answers do not change (an edge left
 * out is under F, as add_seg's own test decides); the work does (docs/viewshed.md
 * "Speed"): picos's sweep went from 376 M to 198 M instructions (callgrind), and F, about
 * two pieces a row, is written once a column; trinidad's 2.23 G -> 1.78 G
 * with the skips, band_lo, and the loops' contexts (tgt_cols, strip_cols: locals the
 * compiler keeps, where sw's fields were reloaded after every byte written to vis). The
 * east and west cones read their columns, strided in the grid, 16 at a time (panel);
 * load_next and the column's bounds (col_bounds) are built for AVX2 as well (820.4 ->
 * 797.3 M, 2026-11-30 16:10).
 * The strip's edges are left out 8 cells at a time where they are under F (block_under)
 * or, where the terrain faces the eye, under the column's polyline (block_facing); col_pass
 * also keeps each row's starting lo (flo), so that sweep_cone decides a target under it
 * without calling target() (trinidad 1.64 G -> 1.40 G, docs/viewshed.md "Speed"), and
 * F's value there (fhi), so that it decides the visible ones too (quick_visible; fhi
 * raised to the last cell's diagonal, for a column's rows that may be visible in one
 * vector pass, last_diags: 903.0 -> 820.4 M, 2026-11-30 16:10); F is
 * kept to the m the columns still to come read (col_merge), facing blocks are tried under
 * the column's polyline alone first (block_poly), and a bilinear target its last cell's
 * upper diagonal leaves undecided is proved hidden by real points of that last strip
 * (last_real): trinidad 1.46 G -> 1.29 G, casts 15,775 -> 9,430 (2026-11-30 07:00).
 *
 * Rounding: the envelope is computed in double from float heights; a crossing put off
 * by rounding moves a value by the slope times 1e-16, kept below 1e-8 by flattening
 * edges narrower than 1e-5 in m. eps (1e-6 m per cell of u, plus 1e-9 relative) is the
 * height 1e-6 m at a cell's distance, a thousand times what either side's rounding
 * reaches; a segment that close to the surface is cast.
 *
 * Alternatives measured (docs/viewshed.md "Speed"): per-wedge horizon bins
 * (horizon.h) to start each cast late; see the doc for why the envelope replaced them. */
#include "vsweep.h"

#include <math.h>
#include <stdio.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "bigalloc.h"
#include "simd.h"
#include "viewshed.h"

#define VS_EPS_ABS 1e-6
#define VS_EPS_REL 1e-9
#define VS_NARROW 1e-5   /* edges narrower than this in m are kept flat */
#define VS_BINS 4096     /* bins of m in [-1, 1] for the holes' nearest distance */
/* The envelope covers m in [-VS_MDOM, VS_MDOM], past the cone's [-1, 1], so that a sample
 * at m = 1 whose only edge lies outside the cone is kept (an edge of zero width would
 * not be). */
#define VS_MDOM 1.5
/* From this u on, every sample of a column (|V - ev| <= u + 2) has |m| < VS_MDOM: the
 * column pass's shortcuts hold there (nearer columns take the general path). */
#define VS_PASS_U 8.0
/* Columns read into the panel at a time (east and west cones): a row's 16 floats are one
 * or two cache lines, instead of a line (and a page) a sample. */
#define VS_PANEL 16
/* Cells of a strip tested as one block (add_strip, block_under) */
#define VS_BLOCK 8
/* Strips nearer than VS_SUB_U cells: bilinear cells whose twist is above VS_SUB_K (u - 1),
 * a quarter of it being their upper diagonal's slack times u - 1, as VS_SUB x VS_SUB
 * sub-cells (add_subcells; measured against other choices in docs/viewshed.md "Speed") */
#define VS_SUB_U 64.0
#define VS_SUB 2
#define VS_SUB_K 0.04
/* Rows whose last cells' diagonals last_diags computes, or skips when none may be visible */
#define VS_DIAG 8
/* last_real's points stop this far (in cells) short of the target */
#define VS_LAST_GAP 1e-3
/* A target's m and the ends of F's pieces are each computed with their own rounding (the
 * column's (V - ev) / u, an edge clipped to the cone at u = v, ...): pieces that come this
 * near a target's m count for its upper bound (f_near_max; |m| < VS_MDOM there, so this is
 * thousands of times the rounding of m) */
#define VS_MTOL 0x1p-40

typedef struct piece {
    double m;      /* start; the piece ends where the next one starts */
    double mr, qr; /* value qr + s (m - mr); qr = -inf: no surface here */
    double s, slack;
    double umax; /* the farthest u of its edge: where a ray meets it, at most */
} piece;

typedef struct pvec {
    piece *p; /* n pieces and p[n], the sentinel whose m is the end (1) */
    int n, cap;
    int own; /* p is malloc'ed (else a slice of its cone worker's scratch, cone_worker) */
} pvec;

typedef struct cone {
    const td_grid *g;
    int ui, uj, vi, vj;
    int strict; /* north and south: |V - ev| < u (the diagonals belong to east and west) */
    int anti;   /* the triangle surface's diagonal is (U+1, V)-(U, V+1) */
    double eu, ev;
    int32_t ulo, uhi, vlo, vhi; /* U, V ranges of the grid */
} cone;

typedef struct sweep {
    const td_vsweep_job *job;
    cone c;
    int tri, bil, lin;
    int holes; /* the grid has void samples */
    int hidden_ok;  /* the segments start above the surface (see near_strip) */
    /* the cells that hold the eye (up to two: the eye on their row line), their corners
     * and the eye's place ae, be in them, and the eye's height over the ground
     * (starts_under_eye) */
    struct {
        double z[4], ae, be;
    } es[2];
    int nes;
    double es_h;
    int visible_ok; /* the eye's strip is bounded (see near_strip) */
    int visible_start; /* else, on the linear surface: bounded where a segment starts over it (target) */
    pvec F, G, T;
    pvec C; /* column U's edges (add_column_pass) */
    pvec N; /* bounds of the eye's strip with no real point (slack infinite): hi only */
    double nmax; /* N's maximum over the domain (n_max) */
    int hint_q, hint_s;
    double umax;              /* of the edges being added */
    /* the nearest u of the edges being added, and the u under which an edge proves
     * nothing hidden (its pieces' slack infinite): add_seg, near_strip */
    double umin, near_u;
    double hole_u[VS_BINS];   /* per bin of m, the nearest u of a hole cell a ray there may cross */
    int oom;
    uint8_t *vis;
    double *zcol[3]; /* columns U-1, U, U+1 (rows vlo.., NaN where not loaded) */
    double *mcol[3], *qcol[3]; /* their samples projected (columns east of the eye) */
    /* column U against F before its edges go in (col_pass): the piece holding each
     * sample's m, F's minimum over each interval [m_V, m_V+1], and a lower bound of F
     * once column U is in (lcol: that minimum, or the column edge's lower end when the
     * edge counts); valid while pass_ok (u >= VS_PASS_U) */
    int *kcol;
    double *fmin, *lcol, *cslope;
    double *fmax; /* F's maximum over each interval [m_V, m_V+1] (col_pass) */
    double *flo;  /* F's piece kcol[V] at m_V less its slack, -inf behind a hole: the lo target() starts from (col_pass) */
    double *fhi;  /* F at m_V (on a break the higher of the two pieces): the hi target() starts from (col_pass) */
    int quick;    /* targets under flo decided in sweep_cone's loop (hidden_ok, no target height) */
    /* east and west cones, whose columns are strided in the grid: VS_PANEL columns from
     * panel_u on, rows panel_v0..panel_v1, read a row's run of floats at a time (panel) */
    float *panel;
    int32_t panel_u, panel_n, panel_v0, panel_v1;
    uint8_t *colok; /* column U's edge [V, V+1] counts (a cell beside it is not a hole) */
    int pass_ok;
    uint64_t swept, rays, steps, blocks, facing;
} sweep;

/* max and min of values that are never NaN here, inline (fmax, fmin are calls to libm) */
static inline double dmax(double a, double b) { return a > b ? a : b; }
static inline double dmin(double a, double b) { return a < b ? a : b; }

/* Two doubles (GCC and clang vector extensions; an SSE2 register): the strip's block tests
 * (block_under, block_poly) two cells at a time, each lane the scalar expression (no FMA
 * in C11 mode: the same bits). */
typedef double vd2 __attribute__((vector_size(16)));
typedef long long vl2 __attribute__((vector_size(16)));
/* dmax and dmin lane by lane (maxpd and minpd are a > b ? a : b and a < b ? a : b) */
#if defined(__SSE2__)
static inline vd2 vmax2(vd2 a, vd2 b) { return (vd2)_mm_max_pd((__m128d)a, (__m128d)b); }
static inline vd2 vmin2(vd2 a, vd2 b) { return (vd2)_mm_min_pd((__m128d)a, (__m128d)b); }
#else
static inline vd2 vmax2(vd2 a, vd2 b) { vd2 r = {dmax(a[0], b[0]), dmax(a[1], b[1])}; return r; }
static inline vd2 vmin2(vd2 a, vd2 b) { vd2 r = {dmin(a[0], b[0]), dmin(a[1], b[1])}; return r; }
#endif
static inline vd2 ld2(const double *p)
{
    vd2 v;
    memcpy(&v, p, sizeof v);
    return v;
}

static const piece empty_piece = {0.0, 0.0, -INFINITY, 0.0, 0.0, 0.0};

static inline double pval(const piece *p, double m) { return p->qr + p->s * (m - p->mr); }

static inline int same_line(const piece *a, const piece *b)
{
    return a->qr == b->qr && a->s == b->s && a->mr == b->mr && a->slack == b->slack && a->umax == b->umax;
}

/* hi raised to the values of the pieces near m: those that end or start within VS_MTOL
 * of m, p[k] the one holding m (p ends with a sentinel piece past every m asked), each at
 * its end nearest m. A segment through a vertex where F drops (the edges beyond it a
 * hole's, or clipped away at the cone's side) must meet the higher piece, though its m may
 * be an ulp past that piece's end (fuzz_viewshed, test_vertex_hole_diagonal: a segment
 * along the eye's diagonal through such a vertex was proved visible under the lower
 * piece; the cast meets the surface there). More pieces only raise an upper bound: fewer
 * proofs, none wrong. */
static double f_near_scan(const piece *p, int k, double m, double hi)
{
    for (int j = k - 1; j >= 0 && p[j + 1].m >= m - VS_MTOL; j--) /* ending at most VS_MTOL before m */
        hi = dmax(hi, pval(&p[j], p[j + 1].m));
    for (int j = k + 1; p[j].m <= m + VS_MTOL; j++) /* starting at most VS_MTOL after it */
        hi = dmax(hi, pval(&p[j], p[j].m));
    return hi;
}

/* f_near_max: the scan only where a break is that near (rarely: inline, one test each way) */
static inline double f_near_max(const piece *p, int k, double m, double hi)
{
    if (p[k].m >= m - VS_MTOL || p[k + 1].m <= m + VS_MTOL)
        hi = f_near_scan(p, k, m, hi);
    return hi;
}

static int pv_reserve(sweep *sw, pvec *v, int need)
{
    if (need + 1 > v->cap) {
        int cap = v->cap ? v->cap : 256;
        piece *p;
        while (cap < need + 1)
            cap *= 2;
        if (v->own) {
            p = realloc(v->p, (size_t)cap * sizeof *p);
        } else if ((p = malloc((size_t)cap * sizeof *p)) && v->cap) { /* out of the scratch */
            memcpy(p, v->p, (size_t)v->cap * sizeof *p);
        }
        if (!p) {
            sw->oom = 1;
            return 0;
        }
        v->p = p;
        v->cap = cap;
        v->own = 1;
    }
    return 1;
}

/* v = no surface over the domain. */
static void pv_clear(pvec *v)
{
    v->p[0] = empty_piece;
    v->p[0].m = -VS_MDOM;
    v->p[1] = empty_piece;
    v->p[1].m = VS_MDOM;
    v->n = 1;
}

/* Appends src's line from m (a piece of zero width is replaced; equal lines join). *last
 * is the source of o's last piece (NULL: not known): the same source joins at once. */
static inline void emit(pvec *o, double m, const piece *src, const piece **last)
{
    int join = o->n > 0 && (src == *last || same_line(&o->p[o->n - 1], src));
    if (!join && o->n > 0 && o->p[o->n - 1].m >= m) {
        o->n--;
        join = o->n > 0 && same_line(&o->p[o->n - 1], src);
    }
    if (!join) {
        o->p[o->n] = *src;
        o->p[o->n].m = m;
        o->n++;
    }
    *last = src;
}

/* The first k >= k0 with k == n or p[k].m >= m (p's starts do not decrease): by steps
 * that double, then halving (the run of F under an empty stretch of the column's pieces
 * is hundreds of pieces long where the terrain is hidden: scanned one by one it was a
 * seventh of merge's time, perf). */
static inline int first_from(const piece *p, int n, int k0, double m)
{
    int lo = k0, hi = k0, step = 1;
    while (hi < n && p[hi].m < m) {
        lo = hi + 1;
        hi += step;
        step *= 2;
    }
    if (hi > n)
        hi = n;
    while (lo < hi) {
        int mid = lo + (hi - lo) / 2;
        if (p[mid].m < m)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo;
}

/* out = max(a, b), both covering [a[0].m, end] with a[na].m = b[nb].m = end; out needs
 * room for 2 (na + nb) + 1 pieces. Ties go to a (the older). */
static void merge(const piece *a, int na, const piece *b, int nb, pvec *outp)
{
    int ia = 0, ib = 0;
    double cur = a[0].m, end = a[na].m;
    const piece *last = NULL;
    pvec o = *outp, *out = &o; /* a local: the stores of pieces and of last leave it in registers */
    out->n = 0;
    while (cur < end && ia < na && ib < nb) {
        double ea, eb, nx;
        const piece *pa, *pb;
        ea = a[ia + 1].m;
        eb = b[ib + 1].m;
        nx = ea < eb ? ea : eb;
        pa = &a[ia];
        pb = &b[ib];
        if (nx > end)
            nx = end;
        if (nx > cur) {
            if (pb->qr == -INFINITY) {
                /* b empty up to eb: a's pieces that start before it, copied whole */
                int k = first_from(a, na, ia + 1, eb);
                emit(out, cur, pa, &last);
                if (k > ia + 1) {
                    emit(out, a[ia + 1].m, &a[ia + 1], &last);
                    memcpy(&out->p[out->n], &a[ia + 2], (size_t)(k - ia - 2) * sizeof *a);
                    out->n += k - ia - 2;
                    last = &a[k - 1];
                    ia = k - 1;
                    ea = a[ia + 1].m;
                    nx = ea < eb ? ea : eb;
                    if (nx > end)
                        nx = end;
                }
            } else if (pa->qr == -INFINITY) {
                emit(out, cur, pb, &last);
            } else {
                double d0 = pval(pa, cur) - pval(pb, cur), d1 = pval(pa, nx) - pval(pb, nx);
                if (d0 >= 0.0 && d1 >= 0.0) {
                    emit(out, cur, pa, &last);
                } else if (d0 <= 0.0 && d1 <= 0.0) {
                    emit(out, cur, pb, &last);
                } else {
                    double c = cur + (nx - cur) * (d0 / (d0 - d1));
                    emit(out, cur, d0 > 0.0 ? pa : pb, &last);
                    emit(out, c > cur ? (c < nx ? c : nx) : cur, d0 > 0.0 ? pb : pa, &last);
                }
            }
            cur = nx;
        }
        if (ea <= cur)
            ia++;
        if (eb <= cur)
            ib++;
    }
    out->p[out->n] = empty_piece;
    out->p[out->n].m = end;
    *outp = o;
}

/* The piece of the n pieces p containing m (p[k].m <= m < p[k+1].m; the last one for
 * m = end), searched from *hint. */
static inline int find_in(const piece *p, int n, double m, int *hint)
{
    int k = *hint;
    if (k >= n)
        k = n - 1;
    while (k > 0 && p[k].m > m)
        k--;
    while (k + 1 < n && p[k + 1].m <= m)
        k++;
    *hint = k;
    return k;
}

/* find_in over v's pieces. */
static int find(const pvec *v, double m, int *hint) { return find_in(v->p, v->n, m, hint); }

/* ---- cone coordinates ------------------------------------------------------------ */

static inline double cz(const cone *c, int32_t U, int32_t V)
{
    int32_t i = c->ui * U + c->vi * V, j = c->uj * U + c->vj * V;
    return (double)c->g->z[(size_t)j * (size_t)c->g->w + (size_t)i];
}

static inline size_t cidx(const cone *c, int32_t U, int32_t V)
{
    int32_t i = c->ui * U + c->vi * V, j = c->uj * U + c->vj * V;
    return (size_t)j * (size_t)c->g->w + (size_t)i;
}

/* Sample (U, V)'s byte in vis (its rows north first with the job's north_first). */
static inline size_t vidx(const cone *c, int north_first, int32_t U, int32_t V)
{
    int32_t i = c->ui * U + c->vi * V, j = c->uj * U + c->vj * V;
    return (size_t)(north_first ? c->g->h - 1 - j : j) * (size_t)c->g->w + (size_t)i;
}

/* Corners z00, z10, z01, z11 of cone cell (U, V) (U..U+1, V..V+1); 0 if it is off the
 * grid or a hole. */
static int cell(const cone *c, int32_t U, int32_t V, double z[4])
{
    int ok = U >= c->ulo && U + 1 <= c->uhi && V >= c->vlo && V + 1 <= c->vhi;
    if (ok) {
        z[0] = cz(c, U, V);
        z[1] = cz(c, U + 1, V);
        z[2] = cz(c, U, V + 1);
        z[3] = cz(c, U + 1, V + 1);
        ok = !isnan(z[0]) && !isnan(z[1]) && !isnan(z[2]) && !isnan(z[3]);
    }
    return ok;
}

static void cone_init(cone *c, const td_grid *g, int k, double eu, double ev)
{
    static const int t[4][5] = {
        /* ui uj vi vj anti */
        {1, 0, 0, 1, 1},  /* east: U = i, V = j */
        {-1, 0, 0, 1, 0}, /* west: U = -i */
        {0, 1, 1, 0, 1},  /* north: U = j, V = i */
        {0, -1, 1, 0, 0}, /* south: U = -j */
    };
    int32_t nu = k < 2 ? g->w : g->h, nv = k < 2 ? g->h : g->w;
    c->g = g;
    c->ui = t[k][0];
    c->uj = t[k][1];
    c->vi = t[k][2];
    c->vj = t[k][3];
    c->anti = t[k][4];
    c->strict = k >= 2;
    c->eu = k < 2 ? (k == 0 ? eu : -eu) : (k == 2 ? ev : -ev);
    c->ev = k < 2 ? ev : eu;
    c->ulo = (k & 1) ? -(nu - 1) : 0;
    c->uhi = (k & 1) ? 0 : nu - 1;
    c->vlo = 0;
    c->vhi = nv - 1;
}

/* The rows column U needs (load_next: the buffers hold columns U-1, U, U+1 for column
 * U's targets and edges): |V - ev| <= u + 3, on the grid. */
static void col_rows(const cone *c, int32_t U, int32_t *V0, int32_t *V1)
{
    double u = U - c->eu;
    *V0 = (int32_t)dmax(floor(c->ev - u) - 3.0, (double)c->vlo);
    *V1 = (int32_t)dmin(ceil(c->ev + u) + 3.0, (double)c->vhi);
}

/* Fills the panel with columns U .. U + VS_PANEL - 1 (those on the grid), the rows the
 * last of them needs (the widest): per row one run of contiguous floats. */
static void panel_fill(sweep *sw, int32_t U)
{
    const cone *c = &sw->c;
    const td_grid *g = c->g;
    int32_t n = c->uhi - U + 1 < VS_PANEL ? c->uhi - U + 1 : VS_PANEL, V0, V1;
    int32_t ilo = c->ui > 0 ? U : -(U + n - 1); /* the run's first grid column */
    size_t nv = (size_t)(c->vhi - c->vlo + 1);
    col_rows(c, U + n - 1, &V0, &V1);
    for (int32_t V = V0; V <= V1; V++) {
        const float *src = g->z + (size_t)V * (size_t)g->w + (size_t)ilo;
        if (V + 8 <= V1) /* 8 rows ahead: each row is a page of its own (the rows' stride) */
            __builtin_prefetch(src + 8 * (size_t)g->w);
        for (int32_t k = 0; k < n; k++)
            sw->panel[(size_t)k * nv + (size_t)(V - c->vlo)] = src[c->ui > 0 ? k : n - 1 - k];
    }
    sw->panel_u = U;
    sw->panel_n = n;
    sw->panel_v0 = V0;
    sw->panel_v1 = V1;
}

/* Column U's heights, rows V0..V1 wanted: src[V] is sample (U, V)'s. From the panel for
 * the east and west cones (filled as needed), else the grid's row (north and south: V is
 * the grid's column). */
static inline const float *col_src(sweep *sw, int32_t U, int32_t V0, int32_t V1)
{
    const cone *c = &sw->c;
    const float *src = c->g->z + cidx(c, U, 0);
    if (sw->panel) {
        if (U < sw->panel_u || U >= sw->panel_u + sw->panel_n || V0 < sw->panel_v0 || V1 > sw->panel_v1)
            panel_fill(sw, U);
        src = sw->panel + (size_t)(U - sw->panel_u) * (size_t)(c->vhi - c->vlo + 1) - c->vlo;
    }
    return src;
}

/* Column U+1 into the buffers (see col_rows): heights, m and q a row, in a loop built for
 * AVX2 as well (four rows to a register, the same operations: trinidad from Blanca Peak
 * 806.0 -> 797.3 M instructions, the valley 370.9 -> 362.2 M). */
TD_ROW_CLONES static void load_next(sweep *sw, int32_t U)
{
    const cone *c = &sw->c;
    double un = U + 1 - c->eu, iu = 1.0 / un, ez = sw->job->ez;
    int32_t V0, V1;
    double *t[3] = {sw->zcol[0], sw->mcol[0], sw->qcol[0]};
    const float *src = NULL;
    col_rows(c, U + 1, &V0, &V1);
    for (int b = 0; b < 2; b++) {
        sw->zcol[b] = sw->zcol[b + 1];
        sw->mcol[b] = sw->mcol[b + 1];
        sw->qcol[b] = sw->qcol[b + 1];
    }
    sw->zcol[2] = t[0];
    sw->mcol[2] = t[1];
    sw->qcol[2] = t[2];
    /* a column off the grid is not loaded (NaN: the buffers' start, or a stale column
     * past the far edge, which nothing reads); before the near edge when the eye's cell
     * coordinate rounds past the grid's last row or column (y = 21 sy over sy: 21 + 1 ulp) */
    if (U + 1 >= c->ulo && U + 1 <= c->uhi)
        src = col_src(sw, U + 1, V0, V1);
    for (int32_t V = V0; V <= V1 && src; V++) {
        double z = src[V];
        t[0][V - c->vlo] = z;
        t[1][V - c->vlo] = (V - c->ev) * iu;
        t[2][V - c->vlo] = (z - ez) * iu;
    }
}

/* Cell between buffered columns a (west) and b at rows V..V+1: corners z00, z10, z01,
 * z11; 0 off the grid or a hole. */
static inline int cellz(const sweep *sw, const double *a, const double *b, int32_t V, double z[4])
{
    int32_t k = V - sw->c.vlo;
    if (V < sw->c.vlo || V + 1 > sw->c.vhi)
        return 0;
    z[0] = a[k];
    z[1] = b[k];
    z[2] = a[k + 1];
    z[3] = b[k + 1];
    return !isnan(z[0] + z[1] + z[2] + z[3]);
}

/* ---- the envelope's updates ------------------------------------------------------ */

/* Whether piece p over [m0, m1] stays at or under F. */
static int under_f(sweep *sw, const piece *p, double m0, double m1)
{
    const pvec *F = &sw->F;
    int k = find(F, m0, &sw->hint_s);
    double x = m0;
    int under = 1;
    for (;;) {
        double xe = F->p[k + 1].m < m1 ? F->p[k + 1].m : m1;
        if (pval(p, x) > pval(&F->p[k], x) || pval(p, xe) > pval(&F->p[k], xe))
            under = 0;
        if (!under || xe >= m1 || k + 1 >= F->n)
            break;
        x = xe;
        k++;
    }
    return under;
}

/* p over [m0, m1] into G (whose pieces after the one holding m0 are few: edges come in
 * about increasing m). */
static void g_insert(sweep *sw, const piece *p, double m0, double m1)
{
    pvec *G = &sw->G, *T = &sw->T;
    piece b[4];
    int k = G->n - 1;
    if (G->p[k].qr == -INFINITY && G->p[k].m <= m0) { /* past everything so far: append */
        if (pv_reserve(sw, G, G->n + 3)) {
            k += G->p[k].m < m0;
            G->p[k] = *p;
            G->p[k].m = m0;
            G->p[k + 1] = empty_piece;
            G->p[k + 1].m = m1;
            G->n = k + (m1 < VS_MDOM ? 2 : 1);
            G->p[G->n] = empty_piece;
            G->p[G->n].m = VS_MDOM;
        }
    } else {
        while (k > 0 && G->p[k].m > m0)
            k--;
        b[0] = empty_piece;
        b[0].m = G->p[k].m;
        b[1] = *p;
        b[1].m = m0;
        b[2] = empty_piece;
        b[2].m = m1;
        b[3] = empty_piece;
        b[3].m = VS_MDOM;
        if (pv_reserve(sw, T, 2 * (G->n - k + 3) + 1) && pv_reserve(sw, G, k + 2 * (G->n - k + 3) + 1)) {
            merge(&G->p[k], G->n - k, b, 3, T);
            memcpy(&G->p[k], T->p, (size_t)(T->n + 1) * sizeof *T->p);
            G->n = k + T->n;
        }
    }
}

/* The projected edge from (ma, qa) to (mb, qb) into G; with `prune`, unless F already
 * covers it. Its line is kept from its end nearer the domain [-VS_MDOM, VS_MDOM] (the one
 * in it, where it has one): an end far outside it (an edge of the first strip when the
 * first column is ulps from the eye, u ~ 4e-15: m ~ 3e14, q ~ 7e14) would leave each value
 * in the domain the difference of two numbers 1e14 apart, off by the slope times 1e-2.
 * Found by fuzz_viewshed: an eye on row line 31 (y = 31 sy, 31.000000000000004 cells)
 * whose first strip's ridge diagonal stood 0.08 too low in F, so a target it hides by 8 mm
 * was proved visible (test_ulp_eye_over_line). */
static void add_seg(sweep *sw, double ma, double qa, double mb, double qb, double slack, int prune)
{
    double m0, m1;
    piece p;
    if (sw->umin < sw->near_u) /* may hold points the tracer does not look at (near_strip) */
        slack = INFINITY;
    if (ma > mb) {
        double t = ma;
        ma = mb;
        mb = t;
        t = qa;
        qa = qb;
        qb = t;
    }
    /* a point in m (its ends are column samples) or off the domain: nothing */
    if (mb > ma && mb >= -VS_MDOM && ma <= VS_MDOM) {
        p.mr = ma;
        p.umax = sw->umax;
        if (mb - ma < VS_NARROW) {
            p.qr = qa > qb ? qa : qb;
            p.s = 0.0;
            p.slack = slack + fabs(qa - qb);
        } else {
            p.qr = qa;
            p.s = (qb - qa) / (mb - ma);
            p.slack = slack;
            if (ma < -VS_MDOM && fabs(mb) < -ma) { /* anchored at its end nearer the domain */
                p.mr = mb;
                p.qr = qb;
            }
        }
        m0 = ma < -VS_MDOM ? -VS_MDOM : ma;
        m1 = mb > VS_MDOM ? VS_MDOM : mb;
        if (m1 > m0 && !(prune && under_f(sw, &p, m0, m1)))
            g_insert(sw, &p, m0, m1);
    }
}

/* The edge from (ua, va, za) to (ub, vb, zb) (u, v from the eye, u > 0) projected, into
 * G unless F already covers it. */
static void add_edge_uv(sweep *sw, double ua, double va, double za, double ub, double vb, double zb,
                        double slack)
{
    double ez = sw->job->ez;
    add_seg(sw, va / ua, (za - ez) / ua, vb / ub, (zb - ez) / ub, slack, 1);
}

/* *dst = max(*dst, *src) (through T; nothing to do when src is empty). */
static void merge_into(sweep *sw, pvec *dst, const pvec *src)
{
    if ((src->n > 1 || src->p[0].qr != -INFINITY) && pv_reserve(sw, &sw->T, 2 * (dst->n + src->n) + 1)) {
        pvec t;
        merge(dst->p, dst->n, src->p, src->n, &sw->T);
        t = *dst;
        *dst = sw->T;
        sw->T = t;
    }
}

/* F = max(F, G). */
static void merge_g(sweep *sw)
{
    merge_into(sw, &sw->F, &sw->G);
    sw->hint_q = sw->hint_s = 0;
}

/* The bilinear cell's upper diagonal (main when its twist k >= 0) and its slack at
 * distance u0 (nearest point of the cell); the triangle's is fixed per cone. */
static inline double upper_slack(const sweep *sw, const double z[4], double u0)
{
    return sw->bil ? fabs(z[0] - z[1] - z[2] + z[3]) / (4.0 * u0) : 0.0;
}

static inline int upper_is_main(const sweep *sw, const double z[4])
{
    return sw->bil ? z[0] - z[1] - z[2] + z[3] >= 0.0 : !sw->c.anti;
}

static int upper_main(const sweep *sw, const double z[4], double u0, double *slack)
{
    double k = z[0] - z[1] - z[2] + z[3];
    *slack = upper_slack(sw, z, u0);
    return sw->bil ? k >= 0.0 : !sw->c.anti;
}

/* floor((m + 1) VS_BINS / 2) clamped to the bins, as a truncation of the positive values
 * (cone_worker is built for the baseline x86-64, where floor is no one instruction: 8.2 M
 * of picos's 123.6 M, the rows' hole tests in col_walk) */
static inline int bin_of(double m)
{
    double b = (m + 1.0) * (VS_BINS / 2.0);
    return b > 0.0 ? (b < VS_BINS ? (int)b : VS_BINS - 1) : 0;
}

/* Holes. The tracer sees a surface only where the segment crosses it inside a cell that
 * has one (a hole cell is passed as if nothing were there), so a segment may enter a
 * cell from a hole already under its surface and leave it into a hole: no crossing.
 * A surface point above the segment proves it hidden only when no hole lies between
 * the eye and that point: hole_u[bin of m] is the nearest u of the hole cells the rays
 * of that bin may cross, and a piece proves only while its umax is nearer. Marks the
 * hole cell at u in [ua, ub], v in [va, vb] (from the eye). */
static void mark_hole(sweep *sw, double ua, double ub, double va, double vb)
{
    double mlo, mhi;
    if (ua > 0.0) {
        mlo = dmin(va / ua, va / ub);
        mhi = dmax(vb / ua, vb / ub);
    } else { /* the cell reaches back to the eye's column: m = v / u with u in (0, ub] */
        mlo = va >= 0.0 ? va / ub : -1.0;
        mhi = vb <= 0.0 ? vb / ub : 1.0;
    }
    for (int b = bin_of(mlo), e = bin_of(mhi); b <= e && mhi >= -1.0 && mlo <= 1.0; b++)
        sw->hole_u[b] = dmin(sw->hole_u[b], dmax(ua, 0.0));
}

/* col_pass's walk over rows V0 .. V1-1 from F's piece k holding m_V0 (returned: the one
 * holding m_V1); inlined twice, with and without holes (hu NULL: its test folds). */
static inline __attribute__((always_inline)) int col_walk(const piece *p, const double *mc, int *kc, double *fm,
                                                          double *fx, double *fl, double *fh, const double *hu,
                                                          int k, int32_t V0, int32_t V1)
{
    /* at: F's piece k at m_V, where the interval before ended (the same k and m, so the
     * same bits as computed again) */
    double at = pval(&p[k], mc[V0]);
    for (int32_t V = V0; V < V1; V++) {
        double m1 = mc[V + 1], lo = at, hi = lo, e;
        fl[V] = lo - p[k].slack;
        if (hu && !(p[k].umax < hu[bin_of(mc[V])])) /* a hole nearer: no lower bound (target()) */
            fl[V] = -INFINITY;
        if (k > 0 && p[k].m == mc[V]) { /* on a break: the piece ending there holds m_V too */
            lo = dmin(lo, pval(&p[k - 1], mc[V]));
            hi = dmax(hi, pval(&p[k - 1], mc[V]));
        }
        /* F drops at a vertex only where the edges beyond it are a hole's (or at the
           cone's sides, col_pass): without holes the walk takes no more tests */
        fh[V] = hu ? f_near_max(p, k, mc[V], hi) : hi;
        while (p[k + 1].m <= m1) {
            double x = p[k + 1].m, y0 = pval(&p[k], x), y1 = pval(&p[k + 1], x);
            lo = dmin(lo, dmin(y0, y1));
            hi = dmax(hi, dmax(y0, y1));
            k++;
        }
        kc[V + 1] = k;
        e = pval(&p[k], m1);
        fm[V] = dmin(lo, e);
        fx[V] = dmax(hi, e);
        at = e;
    }
    return k;
}

/* The column pass over column U's rows V0..V1 (m increasing with V): kcol[V] the piece of
 * F holding m_V (as find), fmin[V] F's minimum over [m_V, m_V+1] (at its ends and the
 * breaks between: F is linear in between), one walk along F instead of a search per
 * target and per edge. Called after load_next(U), before column U's targets and edges.
 * Also flo[V], the lower bound target() starts from (the piece's value less its slack,
 * -inf when a hole is nearer than its edge: hole_u is not changed before the targets),
 * so that sweep_cone decides the hidden ones without calling it: Blanca Peak 1452.6 ->
 * 1423.8 M instructions, the valley sample 596 -> 496 M, picos 145.4 -> 136.5 M. */
static void col_pass(sweep *sw, int32_t U, int32_t V0, int32_t V1)
{
    const piece *p = sw->F.p; /* locals: the stores to kc (int) could alias F's count */
    const double *mc = sw->mcol[1] - sw->c.vlo;
    int *kc = sw->kcol - sw->c.vlo;
    double *fm = sw->fmin - sw->c.vlo, *fx = sw->fmax - sw->c.vlo, *fl = sw->flo - sw->c.vlo;
    double *fh = sw->fhi - sw->c.vlo;
    const double *hu = sw->holes ? sw->hole_u : NULL;
    int k = 0;
    sw->pass_ok = U - sw->c.eu >= VS_PASS_U && U - sw->c.eu < 0.5 / VS_NARROW;
    if (!sw->pass_ok)
        return;
#ifdef TD_VSWEEP_DEBUG
    if (!(p[sw->F.n].m == VS_MDOM && fabs(mc[V0]) < VS_MDOM && fabs(mc[V1]) < VS_MDOM)) {
        fprintf(stderr, "col_pass: F's sentinel at %g, m %g .. %g\n", p[sw->F.n].m, mc[V0], mc[V1]);
        abort();
    }
#endif
    /* one walk: the pieces up to m_V0, then each interval's breaks as k passes them. F's
     * sentinel p[n] starts at VS_MDOM, past every m_V here (|m_V| < VS_MDOM with pass_ok):
     * the walks stop there without a test of k against n */
    while (p[k + 1].m <= mc[V0])
        k++;
    kc[V0] = k;
    k = hu ? col_walk(p, mc, kc, fm, fx, fl, fh, hu, k, V0, V1) : col_walk(p, mc, kc, fm, fx, fl, fh, NULL, k, V0, V1);
    fl[V1] = pval(&p[k], mc[V1]) - p[k].slack;
    fh[V1] = f_near_max(p, k, mc[V1], pval(&p[k], mc[V1]));
    if (hu && !(p[k].umax < hu[bin_of(mc[V1])]))
        fl[V1] = -INFINITY;
    /* the rows at the cone's sides (m = -1, 1), where the eye's strip's edges clipped to
       the cone end (col_walk tested every row where there are holes) */
    for (int32_t V = V0; !hu && V < V1 && mc[V] <= -1.0 + VS_MTOL; V++)
        fh[V] = f_near_max(p, kc[V], mc[V], fh[V]);
    for (int32_t V = V1 - 1; !hu && V > V0 && mc[V] >= 1.0 - VS_MTOL; V--)
        fh[V] = f_near_max(p, kc[V], mc[V], fh[V]);
}

/* Whether an edge of the strip between columns U-1 and U, from (m_a, q_a) on column U
 * (a row's or diagonal's end there, sample Va) to (m_b, q_b) on column U-1, is under F
 * once column U is in. The column's intervals [m_V, m_V+1] it spans are k and k + 1
 * (k + 1 only when `two`); under lcol there, or under the column's polyline: at the
 * far end (the column's line through (m_Va, q_Va) of slope cslope[k] when the far end is
 * in interval k, else through the vertex k + 1) and, spanning two intervals, the edge at
 * the vertex between them. A shortcut before add_seg's exact test (under_f): 0 is "not
 * known". No division: the slopes are per interval, the vertex test cross-multiplied. */
/* Column U's arrays the strip tests read, offset by the rows' origin (one load each
 * per strip, not per edge: the compiler cannot keep sw's fields across add_seg). */
typedef struct strip_cols {
    const double *mc, *qc, *lc, *cs;
    const uint8_t *ok;
    int32_t V0, V1;
    int pass_ok;
} strip_cols;

static inline int under_strip(const strip_cols *x, int32_t k, int two, int32_t Va, double mb, double qb)
{
    const double *mc = x->mc, *qc = x->qc, *lc = x->lc, *cs = x->cs;
    const uint8_t *ok = x->ok;
    double ma = mc[Va], qa = qc[Va], top = dmax(qa, qb);
    int under = top <= lc[k] && (!two || top <= lc[k + 1]);
    if (!under && ok[k] && (!two || ok[k + 1])) {
        int32_t kb = two ? (mb < ma ? k : k + 1) : k; /* the interval of the far end */
        int32_t vx = two ? k + 1 : Va;                /* a vertex on the line of interval kb */
        under = qb <= qc[vx] + cs[kb] * (mb - mc[vx]);
        if (under && two) /* the edge at the vertex m_k+1 at or under q_k+1 */
            under = ((qa - qc[k + 1]) * (mb - mc[k + 1]) - (qb - qc[k + 1]) * (ma - mc[k + 1]) <= 0.0) ==
                    (mb > ma);
    }
    return under;
}

/* The intervals the strip edge from sample Va of column U to m_b (column U-1) spans, for
 * under_strip: 1 and *k (with *two) when they are known, 0 when m_b is past the next
 * interval or the column's rows (the general path then). */
static inline int strip_span(const strip_cols *x, int32_t Va, double mb, int32_t *k, int *two)
{
    const double *mc = x->mc;
    int found;
    if (mb >= mc[Va]) { /* interval Va, or Va and Va + 1 */
        *k = Va;
        found = Va + 1 <= x->V1;
        *two = found && mb > mc[Va + 1];
        found = found && (!*two || (Va + 2 <= x->V1 && mb <= mc[Va + 2]));
    } else { /* interval Va - 1, or Va - 2 and Va - 1 */
        found = Va - 1 >= x->V0;
        *two = found && mb < mc[Va - 1];
        *k = *two ? Va - 2 : Va - 1;
        found = found && (!*two || (Va - 2 >= x->V0 && mb >= mc[Va - 2]));
    }
    return found;
}

/* The strip edge from sample Va of column U to (m_b, q_b) on column U-1: under F once
 * column U is in, as far as the column pass can tell cheaply. */
static inline int strip_under(const strip_cols *x, int32_t Va, double mb, double qb)
{
    int32_t k;
    int two;
    return x->pass_ok && strip_span(x, Va, mb, &k, &two) && under_strip(x, k, two, Va, mb, qb);
}

/* Whether every edge of the strip's cells b .. e-1 (rows and diagonals: their ends are
 * samples b .. e of columns U-1 and U) is under F once column U is in: their m lie in
 * [min(m'_b, m_b), max(m'_e, m_e)] (m increases with V down each column), their q under
 * the highest of those samples', and F with the column is at least lcol over each of the
 * column's intervals that cover that range. 0 when the range is not within the column's
 * intervals V0 .. V1-1 or a sample is void (its hole cells must be marked). The same
 * test as strip_under's first, for a block of cells at a time: an edge it leaves out
 * changes no value of F (docs/viewshed.md "Speed"). */
static inline int block_under(const strip_cols *x, const double *mp, const double *qp, int32_t b, int32_t e)
{
    const double *mc = x->mc, *qc = x->qc, *lc = x->lc;
    double mlo = dmin(mp[b], mc[b]), mhi = dmax(mp[e], mc[e]), top = -INFINITY, low = INFINITY;
    int32_t kl = b, kh = e;
    while (kl > x->V0 && mc[kl] > mlo)
        kl--;
    while (kh < x->V1 && mc[kh] < mhi)
        kh++;
    double sum; /* NaN when a sample is void: its hole cells are marked one by one */
    /* e = b + VS_BLOCK (add_strip): two lanes at a time, then sample e, and the intervals
     * before b and from e the range reaches (one or none). The maxima and minima are exact
     * in any order; the order of the sum changes only its value, not whether it is NaN
     * (the q are finite or NaN), and with a NaN the answer is 0 whatever top and low are */
    vd2 t2 = vmax2(ld2(qp + b), ld2(qc + b)), s2 = ld2(qp + b) + ld2(qc + b), l2 = ld2(lc + b);
    for (int32_t i = 2; i < VS_BLOCK; i += 2) {
        vd2 a = ld2(qp + b + i), c = ld2(qc + b + i);
        t2 = vmax2(t2, vmax2(a, c));
        s2 += a + c;
        l2 = vmin2(l2, ld2(lc + b + i));
    }
    top = dmax(dmax(t2[0], t2[1]), dmax(qp[e], qc[e]));
    sum = s2[0] + s2[1] + qp[e] + qc[e];
    low = dmin(l2[0], l2[1]);
    for (int32_t k = kl; k < b; k++)
        low = dmin(low, lc[k]);
    for (int32_t k = e; k < kh; k++)
        low = dmin(low, lc[k]);
    return mc[kl] <= mlo && mc[kh] >= mhi && top <= low && !isnan(sum);
}

#ifdef TD_VSWEEP_DEBUG /* block_facing's spans against strip_span's */
static void check_span(const strip_cols *x, int32_t Va, double mb, int32_t k, int two)
{
    int32_t k2;
    int two2;
    if (!strip_span(x, Va, mb, &k2, &two2) || k2 != k || two2 != two) {
        fprintf(stderr, "block_facing: span of Va %d mb %.17g: %d %d, strip_span %d %d\n", Va, mb, k, two, k2, two2);
        abort();
    }
}
#define VS_SPAN(x, Va, mb, k, two) check_span(x, Va, mb, k, two)
#else
#define VS_SPAN(x, Va, mb, k, two) ((void)0)
#endif

#ifdef TD_VSWEEP_DEBUG /* the scalar edge tests of block_poly and block_facing (their checks) */
/* under_strip's answer with every test evaluated (no branch: block_facing's edges, where
 * the bilinear cell's diagonal, main or not, is a coin toss for the branch predictor);
 * reads interval k + 1 (a row of the column's, so within the arrays) even without `two`. */
static inline int under_nb(const strip_cols *x, int32_t k, int two, int32_t Va, double mb, double qb)
{
    const double *mc = x->mc, *qc = x->qc, *lc = x->lc, *cs = x->cs;
    double ma = mc[Va], qa = qc[Va], top = dmax(qa, qb);
    int32_t kb = two ? (mb < ma ? k : k + 1) : k, vx = two ? k + 1 : Va;
    int lcu = (top <= lc[k]) & ((!two) | (top <= lc[k + 1]));
    int poly = qb <= qc[vx] + cs[kb] * (mb - mc[vx]);
    int vert = (!two) | ((((qa - qc[k + 1]) * (mb - mc[k + 1]) - (qb - qc[k + 1]) * (ma - mc[k + 1])) <= 0.0) ==
                       (mb > ma));
    return lcu | (x->ok[k] & ((!two) | x->ok[k + 1]) & poly & vert);
}

/* under_nb's test under the column's polyline alone (its second term, ok being 1 without
 * voids): the edge from column sample Va (interval k, and k + 1 with `two`) to (mb, qb),
 * the same expressions; the interval of the far end (kb) and the vertex on its line (vx)
 * given, as under_nb computes them. */
static inline int poly_nb(const strip_cols *x, int32_t k, int two, int32_t Va, int32_t kb, int32_t vx, double mb,
                          double qb)
{
    const double *mc = x->mc, *qc = x->qc, *cs = x->cs;
    double ma = mc[Va], qa = qc[Va];
    int poly = qb <= qc[vx] + cs[kb] * (mb - mc[vx]);
    int vert = (!two) | ((((qa - qc[k + 1]) * (mb - mc[k + 1]) - (qb - qc[k + 1]) * (ma - mc[k + 1])) <= 0.0) ==
                       (mb > ma));
    return poly & vert;
}
#endif

/* block_facing's answer where every edge of the block is under the column's polyline:
 * under_nb's second term alone for each edge, with the intervals block_facing gives it
 * (spelt out: kb and vx as under_nb derives them there), no bound test, no branch. 1:
 * block_facing would answer 1 (each under_nb is this term or'ed with another); 0: not
 * known (block_facing decides). About a third of block_facing's work on facing terrain. */
/* A block test's answer; with TD_VSWEEP_DEBUG checked against the scalar test it stands
 * for (the call is not made otherwise). */
#ifdef TD_VSWEEP_DEBUG
static int vs_checked(const char *what, int got, int want, int32_t b, int32_t e)
{
    if (got != want) {
        fprintf(stderr, "%s: cells %d .. %d: %d, the scalar test %d\n", what, b, e, got, want);
        abort();
    }
    return got;
}
#define VS_CHECKED(what, got, scalar) vs_checked(what, got, scalar, b, e)
#else
#define VS_CHECKED(what, got, scalar) (got)
#endif

#ifdef TD_VSWEEP_DEBUG /* the scalar test block_poly does two cells at a time */
static int block_poly_scalar(const strip_cols *x, const double *mp, const double *qp, const double *zp,
                                  const double *zc, int32_t b, int32_t e, double ev, double u, int lin, int bil, int anti)
{
    int all = 0;
    if (b > ev && e - ev <= u - 2.0 && e + 1 <= x->V1) {
        all = 1;
        for (int32_t V = b; V < e; V++) {
            int main = bil ? zp[V] - zc[V] - zp[V + 1] + zc[V + 1] >= 0.0 : !anti;
            int row = poly_nb(x, V, 0, V, V, V, mp[V], qp[V]);
            int dm = poly_nb(x, V, 0, V + 1, V, V + 1, mp[V], qp[V]);
            int dn = poly_nb(x, V, 1, V, V + 1, V + 1, mp[V + 1], qp[V + 1]);
            all &= row & (lin | (main & dm) | ((!main) & dn));
        }
    } else if (e < ev && ev - b <= u - 2.0 && b - 1 >= x->V0) {
        all = 1;
        for (int32_t V = b; V < e; V++) {
            int main = bil ? zp[V] - zc[V] - zp[V + 1] + zc[V + 1] >= 0.0 : !anti;
            int row = poly_nb(x, V - 1, 0, V, V - 1, V, mp[V], qp[V]);
            int dm = poly_nb(x, V - 1, 1, V + 1, V - 1, V, mp[V], qp[V]);
            int dn = poly_nb(x, V, 0, V, V, V, mp[V + 1], qp[V + 1]);
            all &= row & (lin | (main & dm) | ((!main) & dn));
        }
    }
    return all;
}
#endif

static inline int block_poly(const strip_cols *x, const double *mp, const double *qp, const double *zp,
                             const double *zc, int32_t b, int32_t e, double ev, double u, int lin, int bil, int anti)
{
    const double *mc = x->mc, *qc = x->qc, *cs = x->cs;
    const vl2 lm = {-(long long)lin, -(long long)lin};
    const vl2 fixed = {-(long long)!anti, -(long long)!anti};
    vl2 all = {-1, -1};
    int side = b > ev && e - ev <= u - 2.0 && e + 1 <= x->V1 ? 1 : (e < ev && ev - b <= u - 2.0 && b - 1 >= x->V0 ? -1 : 0);
    /* cells V, V+1 a vector at a time (VS_BLOCK is even), each lane the
     * scalar expression of poly_nb for its cell (the same operations in the same order:
     * the same bits) */
    for (int32_t V = b; V < e && side; V += 2) {
        vd2 zp0 = ld2(zp + V), zc0 = ld2(zc + V), zp1 = ld2(zp + V + 1), zc1 = ld2(zc + V + 1);
        vd2 mp0 = ld2(mp + V), qp0 = ld2(qp + V), mp1 = ld2(mp + V + 1), qp1 = ld2(qp + V + 1);
        vd2 mc0 = ld2(mc + V), qc0 = ld2(qc + V), mc1 = ld2(mc + V + 1), qc1 = ld2(qc + V + 1);
        vl2 main = bil ? (vl2)(zp0 - zc0 - zp1 + zc1 >= 0.0) : fixed, row, dm, dn;
        if (side > 0) {
            vd2 cs0 = ld2(cs + V), cs1 = ld2(cs + V + 1);
            row = (vl2)(qp0 <= qc0 + cs0 * (mp0 - mc0));               /* poly_nb(x, V, 0, V, V, V, ..) */
            dm = (vl2)(qp0 <= qc1 + cs0 * (mp0 - mc1));                /* poly_nb(x, V, 0, V + 1, V, V + 1, ..) */
            dn = (vl2)(qp1 <= qc1 + cs1 * (mp1 - mc1)) &               /* poly_nb(x, V, 1, V, V + 1, V + 1, ..) */
                 ~((vl2)(((qc0 - qc1) * (mp1 - mc1) - (qp1 - qc1) * (mc0 - mc1)) <= 0.0) ^ (vl2)(mp1 > mc0));
        } else {
            vd2 csm = ld2(cs + V - 1), cs0 = ld2(cs + V);
            row = (vl2)(qp0 <= qc0 + csm * (mp0 - mc0));               /* poly_nb(x, V - 1, 0, V, V - 1, V, ..) */
            dm = row &                                                 /* poly_nb(x, V - 1, 1, V + 1, V - 1, V, ..) */
                 ~((vl2)(((qc1 - qc0) * (mp0 - mc0) - (qp0 - qc0) * (mc1 - mc0)) <= 0.0) ^ (vl2)(mp0 > mc1));
            dn = (vl2)(qp1 <= qc0 + cs0 * (mp1 - mc0));                /* poly_nb(x, V, 0, V, V, V, ..) */
        }
        all &= row & (lm | (main & dm) | (~main & dn));
    }
    return VS_CHECKED("block_poly", side != 0 && (all[0] & all[1]) != 0,
                      block_poly_scalar(x, mp, qp, zp, zc, b, e, ev, u, lin, bil, anti));
}

/* Whether every edge of the strip's cells b .. e-1 (rows b .. e-1, each cell's diagonal)
 * passes strip_under's test, so that add_strip would leave each out: where the terrain
 * faces the eye they are under the column's polyline. Without holes only (with them a
 * block holding a void would need its hole cells marked; tried with blocks of no void
 * sample: picos 145.4 -> 143.2 M, not kept: no test could tell it from taking blocks with
 * voids), and on one side of the eye's row, at least two cells inside the cone (|V - ev| <= u - 2): there each
 * edge's far end lies in a known interval (a sample V > ev of column U-1, at m'_V =
 * (V - ev) / (u - 1), is between m_V and m_V+1 of column U; V < ev between m_V-1 and m_V),
 * so strip_span's search is not needed and under_strip is called with the intervals it
 * would find (checked against it with TD_VSWEEP_DEBUG). The first cell with an edge
 * above ends the test (1423.8 -> 1421.3 M instructions on trinidad from Blanca Peak
 * against testing all 16 edges). */
#ifdef TD_VSWEEP_DEBUG /* the scalar test block_facing does two cells at a time */
static int block_facing_scalar(const strip_cols *x, const double *mp, const double *qp, const double *zp,
                                    const double *zc, int32_t b, int32_t e, double ev, double u, int lin, int bil,
                                    int anti)
{
    int all = 1;
    if (b > ev && e - ev <= u - 2.0 && e + 1 <= x->V1) {
        for (int32_t V = b; V < e && all; V++) {
            int diag = 1;
            if (!lin) {
                int main = bil ? zp[V] - zc[V] - zp[V + 1] + zc[V + 1] >= 0.0 : !anti;
                VS_SPAN(x, main ? V + 1 : V, main ? mp[V] : mp[V + 1], V, !main);
                diag = (main & under_nb(x, V, 0, V + 1, mp[V], qp[V])) |
                       ((!main) & under_nb(x, V, 1, V, mp[V + 1], qp[V + 1]));
            }
            VS_SPAN(x, V, mp[V], V, 0);
            all &= under_nb(x, V, 0, V, mp[V], qp[V]) & diag;
        }
    } else if (e < ev && ev - b <= u - 2.0 && b - 1 >= x->V0) {
        for (int32_t V = b; V < e && all; V++) {
            int diag = 1;
            if (!lin) {
                int main = bil ? zp[V] - zc[V] - zp[V + 1] + zc[V + 1] >= 0.0 : !anti;
                VS_SPAN(x, main ? V + 1 : V, main ? mp[V] : mp[V + 1], main ? V - 1 : V, main);
                diag = (main & under_nb(x, V - 1, 1, V + 1, mp[V], qp[V])) |
                       ((!main) & under_nb(x, V, 0, V, mp[V + 1], qp[V + 1]));
            }
            VS_SPAN(x, V, mp[V], V - 1, 0);
            all &= under_nb(x, V - 1, 0, V, mp[V], qp[V]) & diag;
        }
    } else {
        all = 0;
    }
    return all;
}
#endif

static inline int block_facing(const strip_cols *x, const double *mp, const double *qp, const double *zp,
                               const double *zc, int32_t b, int32_t e, double ev, double u, int lin, int bil,
                               int anti)
{
    const double *mc = x->mc, *qc = x->qc, *lc = x->lc, *cs = x->cs;
    const vl2 lm = {-(long long)lin, -(long long)lin}, fixed = {-(long long)!anti, -(long long)!anti};
    vl2 all = {-1, -1};
    int side = b > ev && e - ev <= u - 2.0 && e + 1 <= x->V1 ? 1 : (e < ev && ev - b <= u - 2.0 && b - 1 >= x->V0 ? -1 : 0);
    /* two cells at a time, each lane under_nb's expression for its edge (ok is 1: no voids
     * here), the same operations in the same order; a pair with an edge above ends it */
    for (int32_t V = b; V < e && side && (all[0] & all[1]); V += 2) {
        vd2 zp0 = ld2(zp + V), zc0 = ld2(zc + V), zp1 = ld2(zp + V + 1), zc1 = ld2(zc + V + 1);
        vd2 mp0 = ld2(mp + V), qp0 = ld2(qp + V), mp1 = ld2(mp + V + 1), qp1 = ld2(qp + V + 1);
        vd2 mc0 = ld2(mc + V), qc0 = ld2(qc + V), mc1 = ld2(mc + V + 1), qc1 = ld2(qc + V + 1);
        vd2 lc0 = ld2(lc + V), cs0 = ld2(cs + V);
        vl2 main = bil ? (vl2)(zp0 - zc0 - zp1 + zc1 >= 0.0) : fixed, row, dm, dn, kb;
        if (side > 0) {
            vd2 lc1 = ld2(lc + V + 1), cs1 = ld2(cs + V + 1), t, cb;
            t = vmax2(qc0, qp0); /* under_nb(x, V, 0, V, mp[V], qp[V]) */
            row = (vl2)(t <= lc0) | (vl2)(qp0 <= qc0 + cs0 * (mp0 - mc0));
            t = vmax2(qc1, qp0); /* under_nb(x, V, 0, V + 1, mp[V], qp[V]) */
            dm = (vl2)(t <= lc0) | (vl2)(qp0 <= qc1 + cs0 * (mp0 - mc1));
            t = vmax2(qc0, qp1); /* under_nb(x, V, 1, V, mp[V + 1], qp[V + 1]) */
            kb = (vl2)(mp1 < mc0);
            cb = (vd2)(((vl2)cs0 & kb) | ((vl2)cs1 & ~kb));
            dn = ((vl2)(t <= lc0) & (vl2)(t <= lc1)) |
                 ((vl2)(qp1 <= qc1 + cb * (mp1 - mc1)) &
                  ~((vl2)(((qc0 - qc1) * (mp1 - mc1) - (qp1 - qc1) * (mc0 - mc1)) <= 0.0) ^ (vl2)(mp1 > mc0)));
        } else {
            vd2 lcm = ld2(lc + V - 1), csm = ld2(cs + V - 1), t, cb;
            t = vmax2(qc0, qp0); /* under_nb(x, V - 1, 0, V, mp[V], qp[V]) */
            row = (vl2)(t <= lcm) | (vl2)(qp0 <= qc0 + csm * (mp0 - mc0));
            t = vmax2(qc1, qp0); /* under_nb(x, V - 1, 1, V + 1, mp[V], qp[V]) */
            kb = (vl2)(mp0 < mc1);
            cb = (vd2)(((vl2)csm & kb) | ((vl2)cs0 & ~kb));
            dm = ((vl2)(t <= lcm) & (vl2)(t <= lc0)) |
                 ((vl2)(qp0 <= qc0 + cb * (mp0 - mc0)) &
                  ~((vl2)(((qc1 - qc0) * (mp0 - mc0) - (qp0 - qc0) * (mc1 - mc0)) <= 0.0) ^ (vl2)(mp0 > mc1)));
            t = vmax2(qc0, qp1); /* under_nb(x, V, 0, V, mp[V + 1], qp[V + 1]) */
            dn = (vl2)(t <= lc0) | (vl2)(qp1 <= qc0 + cs0 * (mp1 - mc0));
        }
        all &= row & (lm | (main & dm) | (~main & dn));
    }
    return VS_CHECKED("block_facing", side != 0 && (all[0] & all[1]) != 0,
                      block_facing_scalar(x, mp, qp, zp, zc, b, e, ev, u, lin, bil, anti));
}

/* The bilinear cell (U-1..U, V..V+1) of a strip near the eye (u < VS_SUB_U), whose upper
 * diagonal would stand for it: its VS_SUB x VS_SUB sub-cells' edges instead (the patch on
 * a sub-cell is bilinear with the twist k / VS_SUB^2): the lines a = i / VS_SUB and
 * b = j / VS_SUB across the cell, on which the patch is linear (real, slack 0), and each
 * sub-cell's upper diagonal with its own slack, VS_SUB^2 times smaller. They bound the
 * patch as the cell's upper triangulation does (each sub-cell's is under it: that one is
 * concave, the sub-corners on the patch), and closer: a far target whose segment passes
 * within a quarter twist over the distance of a cell near the eye was cast (from Blanca
 * Peak, most of trinidad's 8,488 casts of visible targets). Only when the cell's diagonal
 * is not left out (the patch is then under the envelope already). */
static void add_subcells(sweep *sw, const double z[4], int32_t V, double u)
{
    const double ez = sw->job->ez, v0 = V - sw->c.ev, k = z[0] - z[1] - z[2] + z[3];
    const double d = 1.0 / VS_SUB, sk = fabs(k) * d * d / 4.0;
    double pm[VS_SUB + 1][VS_SUB + 1], pq[VS_SUB + 1][VS_SUB + 1]; /* the sub-corners projected */
    for (int i = 0; i <= VS_SUB; i++)
        for (int j = 0; j <= VS_SUB; j++) {
            double a = i * d, b = j * d, up = u - 1.0 + a;
            double zz = z[0] + (z[1] - z[0]) * a + (z[2] - z[0]) * b + k * a * b;
            pm[i][j] = (v0 + b) / up;
            pq[i][j] = (zz - ez) / up;
        }
    for (int i = 1; i < VS_SUB; i++) { /* the lines a = i d and b = i d */
        add_seg(sw, pm[i][0], pq[i][0], pm[i][VS_SUB], pq[i][VS_SUB], 0.0, 1);
        add_seg(sw, pm[0][i], pq[0][i], pm[VS_SUB][i], pq[VS_SUB][i], 0.0, 1);
    }
    for (int i = 0; i < VS_SUB; i++)
        for (int j = 0; j < VS_SUB; j++) {
            double slack = sk / (u - 1.0 + i * d);
            if (k >= 0.0)
                add_seg(sw, pm[i][j], pq[i][j], pm[i + 1][j + 1], pq[i + 1][j + 1], slack, 1);
            else
                add_seg(sw, pm[i + 1][j], pq[i + 1][j], pm[i][j + 1], pq[i][j + 1], slack, 1);
        }
}

/* Whether the upper diagonal of the strip's cell (U-1..U, V..V+1), corners z (z00, z10,
 * z01, z11; twist k = z00 - z10 - z01 + z11), may be where q peaks along a ray; where it
 * cannot, the cell's edges (rows, columns) bound it exactly and the diagonal is left out.
 * On a ray v = m u through the cell the patch's height is a + b u + k m u^2, so
 * q = A / u + B + k m u. With k m >= 0, q rises to the exit (A <= 0) or is convex (A > 0):
 * either way its maximum is at the cell's boundary, so a bilinear cell on one side of the
 * eye's row (m of one sign) needs its diagonal only where k m < 0 (the diagonal's slack,
 * |k| / 4 over the distance, then covers the peak inside). A triangle's diagonal is a real
 * edge, but along a ray q is monotone on each of its two planes, so their seam is a peak
 * only where it is a ridge: the main diagonal where k > 0, the other where k < 0. On
 * trinidad from Blanca Peak: casts 5,182 -> 4,629, the sweep 797.3 -> 770.9 M
 * instructions (triangle 711.2 -> 689.0 M); the same bytes on the 21 cases. */
static inline int diag_counts(int bil, int anti, const double z[4], int32_t V, double ev)
{
    double k = z[0] - z[1] - z[2] + z[3];
    return bil ? !((V >= ev && k >= 0.0) || (V + 1 <= ev && k <= 0.0)) : (anti ? k < 0.0 : k > 0.0);
}

/* The edges of the strip between columns U-1 and U (rows, diagonals) into G, but those
 * the column pass shows under F once column U is in; marks the strip's holes. A block
 * of VS_BLOCK cells at a time when block_under leaves them all out (none is a hole). */
TD_ROW_CLONES static void add_strip(sweep *sw, int32_t V0, int32_t V1, double u)
{
    const cone *c = &sw->c;
    const int32_t o = c->vlo;
    const double *zp = sw->zcol[0], *zc = sw->zcol[1];
    const double *mp = sw->mcol[0] - o, *qp = sw->qcol[0] - o;
    const double *mc = sw->mcol[1] - o, *qc = sw->qcol[1] - o, *zpo = zp - o, *zco = zc - o;
    const strip_cols x = {mc, qc, sw->lcol - o, sw->cslope - o, sw->colok - o, V0, V1, sw->pass_ok};
    const int lin = sw->lin, bil = sw->bil, anti = c->anti, holes = sw->holes;
    const int blocks = sw->pass_ok;
    const int *kc = sw->kcol - o;
    double zl[4] = {0.0, 0.0, 0.0, 0.0}, zb[4]; /* zl read only when `left` (GCC cannot tell) */
    for (int32_t V = V0, below = cellz(sw, zp, zc, V0 - 1, zb), bend = V0; V <= V1 && !sw->oom; V++) {
        int left;
        if (blocks && V == bend) { /* a new block: left out whole when it is under F */
            bend = V + VS_BLOCK;
            int under = bend <= V1 && block_under(&x, mp, qp, V, bend);
            int facing = bend <= V1 && !under && !holes &&
                         (block_poly(&x, mp, qp, zpo, zco, V, bend, c->ev, u, lin, bil, anti) ||
                          block_facing(&x, mp, qp, zpo, zco, V, bend, c->ev, u, lin, bil, anti));
            if (under || facing) {
                sw->blocks++;
                sw->facing += (uint64_t)facing;
                V = bend - 1;
                below = cellz(sw, zp, zc, V, zb);
                continue;
            }
        }
        if (blocks) /* add_seg's search of F (under_f) from the piece of m_V (col_pass) */
            sw->hint_s = kc[V];
        left = cellz(sw, zp, zc, V, zl);
        if (!left && holes && V >= c->vlo && V + 1 <= c->vhi)
            mark_hole(sw, u - 1.0, u, V - c->ev, V + 1 - c->ev);
        if ((left || below) && !strip_under(&x, V, mp[V], qp[V]))
            add_seg(sw, mp[V], qp[V], mc[V], qc[V], 0.0, 1);
        below = left;
        if (left && !lin && diag_counts(bil, anti, zl, V, c->ev)) { /* upper_main's diagonal; its slack (a division) if kept */
            double k = zl[0] - zl[1] - zl[2] + zl[3];
            int main = bil ? k >= 0.0 : !anti;
            /* the diagonal from (m_a, q_a) on column U to (m_b, q_b) on column U-1 */
            double ma = main ? mc[V + 1] : mc[V], qa = main ? qc[V + 1] : qc[V];
            double mb = main ? mp[V] : mp[V + 1], qb = main ? qp[V] : qp[V + 1];
            if (!strip_under(&x, main ? V + 1 : V, mb, qb)) {
                if (bil && u < VS_SUB_U && fabs(k) > VS_SUB_K * (u - 1.0))
                    add_subcells(sw, zl, V, u);
                else
                    add_seg(sw, mb, qb, ma, qa, upper_slack(sw, zl, u - 1.0), 1);
            }
        }
    }
}

/* ok[V] for V0 .. V1-1: a cell beside interval V of column U has no void corner, the one
 * between columns U-1 and U (zp, zc) or between U and U+1 (zc, zn; NULL: U is the last),
 * as cellz decides for rows on the grid; in a loop the compiler vectorises. */
TD_ROW_CLONES static void col_ok(const double *zp, const double *zc, const double *zn, uint8_t *ok, int32_t V0,
                                 int32_t V1)
{
    for (int32_t V = V0; V < V1; V++) {
        int l = !isnan(zp[V] + zc[V] + zp[V + 1] + zc[V + 1]);
        int r = zn && !isnan(zc[V] + zn[V] + zc[V + 1] + zn[V + 1]);
        ok[V] = (uint8_t)(l | r);
    }
}

/* col_bounds' values where ok[V] is 0 (no cell beside the interval): F's minimum and no
 * slope, as add_column_pass had them; returns whether a column edge that counts is above
 * F's minimum (what col_merge would put in). Branch-free, for the compiler to vectorise. */
TD_ROW_CLONES static int col_holes(const uint8_t *ok, const double *qc, const double *fm, double *lc, double *cs,
                                   int32_t V0, int32_t V1)
{
    int above = 0;
    for (int32_t V = V0; V < V1; V++) {
        int o = ok[V] != 0;
        lc[V] = o ? lc[V] : fm[V];
        cs[V] = o ? cs[V] : 0.0;
        above |= o & (dmax(qc[V], qc[V + 1]) > fm[V]);
    }
    return above;
}

/* Column U's edges, and with `strip` those between columns U-1 and U, into F, without
 * the column pass (the columns nearest the eye): the column first, merged, then the
 * strip's rows and diagonals tested against F with it (where the terrain faces the eye
 * they are under it). An edge whose two ends are under one piece of F is under F. */
static void add_column_near(sweep *sw, int32_t U, int strip, int32_t V0, int32_t V1)
{
    const cone *c = &sw->c;
    const double *zp = sw->zcol[0], *zc = sw->zcol[1], *zn = sw->zcol[2];
    const double *mc = sw->mcol[1] - c->vlo, *qc = sw->qcol[1] - c->vlo;
    double z[4], zl[4];
    int hint = sw->hint_s, k0 = find(&sw->F, mc[V0], &hint), k1;
    int under0 = qc[V0] <= pval(&sw->F.p[k0], mc[V0]), under1;
    pv_clear(&sw->G);
    for (int32_t V = V0; V < V1 && !sw->oom; V++, k0 = k1, under0 = under1) {
        k1 = find(&sw->F, mc[V + 1], &hint);
        under1 = qc[V + 1] <= pval(&sw->F.p[k1], mc[V + 1]);
        if ((k0 != k1 || !under0 || !under1) && ((U < c->uhi && cellz(sw, zc, zn, V, z)) || cellz(sw, zp, zc, V, zl)))
            add_seg(sw, mc[V], qc[V], mc[V + 1], qc[V + 1], 0.0, 0);
    }
    merge_g(sw);
    pv_clear(&sw->G);
    if (strip)
        add_strip(sw, V0, V1, U - c->eu);
    merge_g(sw);
}

/* o += F's pieces j0 .. j1-1, the first from m (F's pieces after it start after m, none
 * of zero width, no two neighbours on one line: copied whole, as emit would append each). */
static inline void f_run(pvec *o, const piece *F, int j0, int j1, double m, const piece **last)
{
    emit(o, m, &F[j0], last);
    if (j1 > j0 + 1) {
        memcpy(&o->p[o->n], &F[j0 + 1], (size_t)(j1 - j0 - 1) * sizeof *F);
        o->n += j1 - j0 - 1;
        *last = &F[j1 - 1];
    }
}

/* out += max(a, b) over [x0, x1), as merge computes it: a[ia] and b[ib] the pieces
 * holding x0, each piece ending where the next starts (a's na-th, b's nb-th piece, or x1:
 * a piece past them is not read). Where b is empty, a's pieces are copied whole. */
static void merge_span(pvec *out, const piece *a, int ia, int na, const piece *b, int ib, int nb, double x0,
                       double x1, const piece **last)
{
    double cur = x0;
    while (cur < x1) {
        double ea = ia + 1 < na ? a[ia + 1].m : x1, eb = ib + 1 < nb ? b[ib + 1].m : x1;
        double nx = dmin(dmin(ea, eb), x1);
        const piece *pa = &a[ia], *pb = &b[ib];
        if (nx > cur) {
            if (pb->qr == -INFINITY) { /* b empty up to eb: a's pieces that start before it */
                int k = first_from(a, na, ia + 1, dmin(eb, x1));
                emit(out, cur, pa, last);
                if (k > ia + 1) {
                    memcpy(&out->p[out->n], &a[ia + 1], (size_t)(k - ia - 1) * sizeof *a);
                    out->n += k - ia - 1;
                    *last = &a[k - 1];
                    ia = k - 1;
                    ea = ia + 1 < na ? a[ia + 1].m : x1;
                    nx = dmin(dmin(ea, eb), x1);
                }
            } else if (pa->qr == -INFINITY) {
                emit(out, cur, pb, last);
            } else {
                double d0 = pval(pa, cur) - pval(pb, cur), d1 = pval(pa, nx) - pval(pb, nx);
                if (d0 >= 0.0 && d1 >= 0.0) {
                    emit(out, cur, pa, last);
                } else if (d0 <= 0.0 && d1 <= 0.0) {
                    emit(out, cur, pb, last);
                } else {
                    double c = cur + (nx - cur) * (d0 / (d0 - d1));
                    emit(out, cur, d0 > 0.0 ? pa : pb, last);
                    emit(out, c > cur ? (c < nx ? c : nx) : cur, d0 > 0.0 ? pb : pa, last);
                }
            }
            cur = nx;
        }
        if (ea <= cur && ia + 1 < na)
            ia++;
        if (eb <= cur && ib + 1 < nb)
            ib++;
    }
}

/* Where col_merge is in G: i the piece holding the last span's start, nx the first piece
 * after i with a surface (or G's count), G empty over [.., free) from there. */
typedef struct gpos {
    int i, nx;
    double free;
} gpos;

/* Whether G has a piece with a surface in [x0, x1) (the spans come in increasing m). */
static inline int g_in(const pvec *G, gpos *g, double x0, double x1)
{
    int any = 0;
    if (x1 > g->free) {
        while (g->i + 1 < G->n && G->p[g->i + 1].m <= x0)
            g->i++;
        if (g->nx <= g->i)
            for (g->nx = g->i + 1; g->nx < G->n && G->p[g->nx].qr == -INFINITY; g->nx++)
                ;
        any = G->p[g->i].qr != -INFINITY || (g->nx < G->n && G->p[g->nx].m < x1);
        g->free = any ? x0 : (g->nx < G->n ? G->p[g->nx].m : VS_MDOM);
    }
    return any;
}

/* o += F over [x0, x1) (F's pieces j0 .. j1-1, j0 holding x0), with G's pieces there
 * (merge_span) when it has any. */
static inline void f_span(pvec *o, const piece *F, int j0, int j1, const pvec *G, gpos *g, double x0, double x1,
                          const piece **last)
{
    if (g_in(G, g, x0, x1))
        merge_span(o, F, j0, j1, G->p, g->i, G->n, x0, x1, last);
    else
        f_run(o, F, j0, j1, x0, last);
}

/* C = max(F, column U's edges, G: the strip's survivors), from the column pass's walk
 * (kcol: F's piece at each m_V; fmin, fmax over each interval), without building the
 * column's pieces and merging twice (the column's with G's, then with F, each a copy):
 * per interval [m_V, m_V+1] F's own pieces where the column's edge does not count or is
 * under F (fmin), the edge alone where it is above F's maximum by far more than rounding,
 * else the edge against F's pieces there as merge compares them; where G has pieces,
 * max(F, max(edge, G)) by merge_span. F's pieces outside [mlo, mhi] are left out: no
 * later column reads F there (its samples and its strip's ends on column U'-1, rows vlo ..
 * vhi at u' - 1 >= u, have m in [(vlo - ev) / u, (vhi - ev) / u] and |m| <= (u + 3) / u),
 * so the one piece reaching across each bound stands for F beyond it. */
static void col_merge(sweep *sw, int32_t V0, int32_t V1, double u)
{
    const int32_t o = sw->c.vlo;
    const double *mc = sw->mcol[1] - o, *qc = sw->qcol[1] - o, *fm = sw->fmin - o, *cs = sw->cslope - o;
    const double *fx = sw->fmax - o;
    const uint8_t *ok = sw->colok - o;
    const int *kc = sw->kcol - o;
    const piece *F = sw->F.p;
    const pvec *G = &sw->G;
    const int nf = sw->F.n;
    double lim = (u + 3.0) / u + 1e-9;
    double mlo = dmax(-lim, dmin(0.0, sw->c.vlo - sw->c.ev) / u - 1e-9);
    double mhi = dmin(lim, dmax(0.0, sw->c.vhi - sw->c.ev) / u + 1e-9);
    const piece *last = NULL;
    pvec out, *L = &sw->T;
    gpos gi = {0, 0, -VS_MDOM};
    int a0, b0, run = -1; /* run: the first interval of a run where F stays (-1: none) */
    if (!pv_reserve(sw, &sw->C, 2 * (nf + G->n + 2 * (V1 - V0)) + 8) || !pv_reserve(sw, L, 2 * G->n + 8))
        return;
    out = sw->C;
    out.n = 0;
    a0 = first_from(F, nf, 0, mlo); /* the first piece starting at or past mlo */
    a0 = a0 > 0 ? a0 - 1 : 0;       /* the one holding mlo (m_V0 > mlo: a0 <= kc[V0]) */
    b0 = first_from(F, nf, a0 + 1, mhi);
    f_span(&out, F, a0, kc[V0] + (F[kc[V0]].m < mc[V0]), G, &gi, -VS_MDOM, mc[V0], &last);
    for (int32_t V = V0; V < V1; V++) {
        double m0, m1, q0, q1, top;
        piece e[2];
        int gin;
        if (!ok[V] || dmax(qc[V], qc[V + 1]) <= fm[V]) { /* a run where F stays, to its end */
            run = V;
            while (++V < V1 && (!ok[V] || dmax(qc[V], qc[V + 1]) <= fm[V]))
                ;
            if (V == V1)
                break;
        }
        m0 = mc[V];
        m1 = mc[V + 1];
        q0 = qc[V];
        q1 = qc[V + 1];
        if (run >= 0) /* F over [m_run, m_V) */
            f_span(&out, F, kc[run], kc[V] + (F[kc[V]].m < m0), G, &gi, mc[run], m0, &last);
        run = -1;
        top = dmin(q0, q1);
        gin = g_in(G, &gi, m0, m1);
        if (!gin && top > fx[V] + 1e-9 * (1.0 + fabs(top))) {
            /* appended as emit would: its line is no other piece's (umax = u is this
             * column's alone), so it joins nothing; emit when it must replace a piece of
             * zero width */
            piece *d = &out.p[out.n];
            if (d[-1].m < m0) {
                *d = (piece){m0, m0, q0, cs[V], 0.0, u};
                out.n++;
                last = NULL;
                continue;
            }
        }
        e[0] = (piece){m0, m0, q0, cs[V], 0.0, u};
        e[1] = empty_piece;
        e[1].m = m1;
        if (gin) { /* the edge with G's pieces there (L), then with F */
            const piece *lt = NULL;
            L->n = 0;
            merge_span(L, e, 0, 1, G->p, gi.i, G->n, m0, m1, &lt);
            L->p[L->n] = empty_piece;
            L->p[L->n].m = m1;
            merge_span(&out, F, kc[V], nf, L->p, 0, L->n, m0, m1, &last);
        } else if (top > fx[V] + 1e-9 * (1.0 + fabs(top))) {
            emit(&out, m0, &e[0], &last);
        } else { /* the edge against F's pieces kc[V] .. over [m0, m1], as merge_span */
            double cur = m0;
            for (int k = kc[V]; cur < m1; k++) {
                const piece *pa = &F[k];
                double nx = dmin(F[k + 1].m, m1);
                if (nx > cur) {
                    double d0 = pval(pa, cur) - pval(e, cur), d1 = pval(pa, nx) - pval(e, nx);
                    if (pa->qr == -INFINITY || (d0 <= 0.0 && d1 <= 0.0)) {
                        emit(&out, cur, e, &last);
                    } else if (d0 >= 0.0 && d1 >= 0.0) {
                        emit(&out, cur, pa, &last);
                    } else {
                        double c = cur + (nx - cur) * (d0 / (d0 - d1));
                        emit(&out, cur, d0 > 0.0 ? pa : e, &last);
                        emit(&out, c > cur ? (c < nx ? c : nx) : cur, d0 > 0.0 ? e : pa, &last);
                    }
                    cur = nx;
                }
            }
        }
        /* e and L's pieces are gone: a later piece at their address would be taken for
         * theirs (emit joins F's next piece by same_line all the same) */
        last = NULL;
    }
    run = run < 0 ? V1 : run;
    f_span(&out, F, kc[run], b0, G, &gi, mc[run], VS_MDOM, &last);
    out.p[out.n] = empty_piece;
    out.p[out.n].m = VS_MDOM;
    sw->C = out;
}

/* add_column_pass's bounds of intervals V0 .. V1-1 without voids (lcol, cslope), in a loop
 * the compiler runs two intervals to a register, four in the AVX2 clone (the same
 * operations, so the same bits): trinidad from Blanca Peak 820.4 -> 806.0 M instructions,
 * the valley 385.3 -> 370.9 M (the division four to a register). */
TD_ROW_CLONES static void col_bounds(const double *mc, const double *qc, const double *fm, double *lc, double *cs,
                                     int32_t V0, int32_t V1)
{
    for (int32_t V = V0; V < V1; V++) {
        lc[V] = dmax(fm[V], dmin(qc[V], qc[V + 1]));
        cs[V] = (qc[V + 1] - qc[V]) / (mc[V + 1] - mc[V]);
    }
}

/* Column U's edges and with `strip` the strip's into F, with the column pass: the
 * column's bounds per interval (colok, lcol, cslope) first, so the strip's edges are
 * tested against F with the column in before it is; then one merge of F with the
 * column's pieces and the strip's survivors. */
static void add_column_pass(sweep *sw, int32_t U, int strip, int32_t V0, int32_t V1)
{
    const cone *c = &sw->c;
    const double *zp = sw->zcol[0], *zc = sw->zcol[1], *zn = sw->zcol[2];
    const double *mc = sw->mcol[1] - c->vlo, *qc = sw->qcol[1] - c->vlo, *fm = sw->fmin - c->vlo;
    double *lc = sw->lcol - c->vlo, *cs = sw->cslope - c->vlo, u = U - c->eu;
    uint8_t *ok = sw->colok - c->vlo;
    const int holes = sw->holes;
    int above = 0; /* column edges above F's minimum: those col_merge puts in */
    /* without voids every cell beside the column is there (the rows V0 .. V1 of columns
     * U-1 .. U+1 are loaded and on the grid): the loop without a branch (col_bounds) */
    if (!holes) {
        memset(ok + V0, 1, (size_t)(V1 > V0 ? V1 - V0 : 0));
        col_bounds(mc, qc, fm, lc, cs, V0, V1);
        for (int32_t V = V0; V < V1 && !above; V++)
            above = dmax(qc[V], qc[V + 1]) > fm[V];
    }
    /* with voids: the same bounds where a cell beside the interval is there (col_ok), else
     * F's minimum and no slope; rows V0 .. V1 are on the grid, so cellz's test of them is
     * not needed. Picos from its centre (callgrind, td_vsweep): 123.6 -> 116.4 M with
     * bin_of, 108.7 M with these loops (a branch a row before), 101.3 M with col_holes
     * and targets_plain taking void grids. */
    if (holes) {
        col_ok(zp - c->vlo, zc - c->vlo, U < c->uhi ? zn - c->vlo : NULL, ok, V0, V1);
        col_bounds(mc, qc, fm, lc, cs, V0, V1);
        above = col_holes(ok, qc, fm, lc, cs, V0, V1);
    }
    pv_clear(&sw->G);
    if (strip)
        add_strip(sw, V0, V1, u);
    /* nothing to put in (the whole column and strip under F, as often behind a ridge):
     * F stays as it is, uncopied (and untrimmed this column) */
    if (above || sw->G.n > 1 || sw->G.p[0].qr != -INFINITY)
        col_merge(sw, V0, V1, u);
    if (!sw->oom && (above || sw->G.n > 1 || sw->G.p[0].qr != -INFINITY)) {
        pvec t;
        t = sw->F;
        sw->F = sw->C;
        sw->C = t;
    }
    sw->hint_q = sw->hint_s = 0;
}

/* Column U's edges, and with `strip` those between columns U-1 and U, into F. */
static void add_column(sweep *sw, int32_t U, int strip)
{
    const cone *c = &sw->c;
    double u = U - c->eu;
    int32_t V0 = (int32_t)dmax(floor(c->ev - u) - 1.0, (double)c->vlo);
    int32_t V1 = (int32_t)dmin(ceil(c->ev + u) + 1.0, (double)c->vhi);
    sw->umax = u;
    sw->umin = strip ? u - 1.0 : u;
    if (sw->pass_ok)
        add_column_pass(sw, U, strip, V0, V1);
    else
        add_column_near(sw, U, strip, V0, V1);
}

/* Adds the edge from (ua, va, za) to (ub, vb, zb) (u, v from the eye), clipped to the
 * cone u >= |v|, to G unless F covers it: the edges of the eye's strip, which may pass
 * by or through the eye (one through the eye is a single m: its far end is a column
 * sample, or a point of an edge added here). */
static void add_clipped(sweep *sw, double ua, double va, double za, double ub, double vb, double zb,
                        double slack)
{
    double t0 = 0.0, t1 = 1.0, du = ub - ua, dv = vb - va;
    /* u - v >= 0, u + v >= 0 on [t0, t1] */
    double f0[2] = {ua - va, ua + va}, df[2] = {du - dv, du + dv}, u0, u1;
    for (int k = 0; k < 2; k++) {
        if (df[k] == 0.0)
            t1 = f0[k] < 0.0 ? -1.0 : t1; /* parallel to the side, outside: nothing */
        else if (df[k] > 0.0)
            t0 = dmax(t0, -f0[k] / df[k]);
        else
            t1 = dmin(t1, -f0[k] / df[k]);
    }
    u0 = ua + t0 * du;
    u1 = ua + t1 * du;
    sw->umin = dmin(u0, u1);
    if (t1 > t0 && u0 > 0.0 && u1 > 0.0) /* else outside the cone, or through the eye */
        add_edge_uv(sw, u0, va + t0 * dv, za + t0 * (zb - za), u1, va + t1 * dv, za + t1 * (zb - za), slack);
}

/* The bilinear eye cell's bound over m in [lo, hi] (one sign): the maximum over u of
 * -h / u + ga + gb m - |k m| u is g(m) = ga + gb m - 2 sqrt(h |k| |m|) (kh = |k| h) at
 * u = sqrt(h / |k m|); where that is past the ray's exit from the cell, q rises all the
 * way and peaks at the exit, an edge. The exit is at u0 or, through the row line d away
 * on the side of m's sign, at d / |m|: the peak is inside for a < |m| < d^2 |k| / h. g is
 * convex in m on each side of 0, so under its chords: 16 of them, closer near the start
 * where the root is steep. An eye a hair from a row line (d 1e-7 cells) has a range of
 * 1e-14 left: taken to the cone's side instead, g (Blanca Peak's steep summit cell: ga
 * 131, gb -84 m a cell) stood above every segment's q and no target past the summit was
 * proved visible (111,508 casts instead of 4,623).
 *
 * g(m) is the surface's own q at the peak, a real point: each chord's slack is its sag
 * over g (at sqrt|m| halfway between its ends' roots) with the 1e-9 it is raised by, and
 * the rounding of q at the nearest peak (the chord's far end: u = sqrt(h / |k m1|)), so
 * the pieces prove targets hidden too when they go to G (near_strip: where every peak is
 * past near_u). In N they proved nothing: from Blanca Peak 0.3 cells east and 0.2 south
 * of its sample, where the summit's flank rises 27 m over the eye 0.3 cells away (q 90 on
 * the rays m -1 .. -0.2 of the west cone), 40,311 casts, not 3,669. */
static void eye_cell_bound(sweep *sw, double ga, double gb, double kh, double k, double u0, double d, double lo,
                           double hi)
{
    /* lo or hi is 0; below |m| = a the peak u = sqrt(h / |k m|) is past u0, above
     * d^2 |k| / h past d / |m| (with 2^-20 of it to spare for rounding; kh = 0: never) */
    double a = kh / (k * k * u0 * u0), b = dmax(fabs(lo), fabs(hi)), sg = hi > 0.0 ? 1.0 : -1.0;
    double h = kh / fabs(k), c = sqrt(kh), ez = fabs(sw->job->ez);
    if (kh > 0.0)
        b = dmin(b, d * d * (k * k) / kh * (1.0 + 0x1p-20));
    for (int i = 0; i < 16 && a < b; i++) {
        double f0 = (double)i / 16.0, f1 = (double)(i + 1) / 16.0;
        double x0 = a + (b - a) * f0 * f0, x1 = a + (b - a) * f1 * f1, m0 = sg * x0, m1 = sg * x1;
        double g0 = ga + gb * m0 - 2.0 * c * sqrt(x0), g1 = ga + gb * m1 - 2.0 * c * sqrt(x1);
        /* the chord of -2 c sqrt(x) over it at sqrt(x) = (r0 + r1) / 2 */
        double r0 = sqrt(x0), r1 = sqrt(x1), sag = c * (r1 - r0) * (r1 - r0) / (2.0 * (r0 + r1));
        sw->umin = sqrt(h / (fabs(k) * x1));
        add_seg(sw, m0, g0 + 1e-9 * fabs(g0), m1, g1 + 1e-9 * fabs(g1),
                sag + 2e-9 * (1.0 + fabs(g0) + fabs(g1)) + 0x1p-30 * (1.0 + ez) / sw->umin, 1);
    }
}

/* The maximum of v's pieces over the domain (at their ends: each is linear), -inf when
 * v is empty. A target whose q is above it by eps is above v wherever it is. */
static double n_max(const pvec *v)
{
    double mx = -INFINITY;
    for (int k = 0; k < v->n; k++)
        if (v->p[k].qr != -INFINITY)
            mx = dmax(mx, dmax(pval(&v->p[k], v->p[k].m), pval(&v->p[k], v->p[k + 1].m)));
    return mx;
}

/* G and N exchanged: what is added goes to N, the eye's strip's bounds. */
static void swap_gn(sweep *sw)
{
    pvec t = sw->G;
    sw->G = sw->N;
    sw->N = t;
}

/* The eye's strip: cells U0-1 .. U0 (u from 0, or from the eye, to u0 = U0 - eu <= 1).
 * Its rows and diagonals, clipped; the pieces of cells that hold the eye reach their
 * maximum q where a ray leaves them (q = -height / u + slope, increasing), except the
 * bilinear patch, whose height along a ray from the eye is ground + s(m) u + k m u^2:
 * where k m < 0, q = -height / u + s(m) + k m u may peak inside, below s(m), a line in m
 * (slack infinite: no real point). Sets hidden_ok and visible_ok. */
static void near_strip(sweep *sw, int32_t U0)
{
    const cone *c = &sw->c;
    const td_vsweep_job *j = sw->job;
    int32_t Uc = U0 - 1;
    double u0 = U0 - c->eu, uc = Uc - c->eu, z[4] = {0.0, 0.0, 0.0, 0.0}, twist = 0.0, h = j->ez - j->ground;
    double slope = 0.0; /* a bound of |dz/du| + |dz/dv| in the cells that hold the eye */
    pv_clear(&sw->G);
    pv_clear(&sw->N);
    sw->umax = u0;
    /* The tracer starts a segment 2^-30 of it from the eye, 2^-30 u_T in u: a surface point
     * nearer than that is not looked at, so it proves no target hidden (the segment may
     * cross the surface before the tracer starts it and run above it after). Only edges
     * that pass that near the eye have such points: the eye's strip's rows when the eye is
     * that near a row's line, the first column and strip when it is that near a column's
     * (an eye 1 ulp under an inner row's line, its first column 4e-15 away: without this,
     * 363 samples of test_ulp_eyes differ from the cast; found by fuzz_viewshed). They
     * keep bounding (slack infinite). */
    sw->near_u = 0x1p-28 * (1.0 + c->uhi - c->eu);
    sw->nes = 0;
    for (int32_t V = (int32_t)floor(c->ev - u0) - 1; V <= (int32_t)ceil(c->ev + u0) + 1; V++) {
        int here = cell(c, Uc, V, z), eye;
        double zb[4];
        if (V < c->vlo || V > c->vhi)
            continue;
        if (!here && V + 1 <= c->vhi)
            mark_hole(sw, uc, u0, V - c->ev, V + 1 - c->ev);
        if (here || cell(c, Uc, V - 1, zb))
            add_clipped(sw, uc, V - c->ev, cz(c, Uc, V), u0, V - c->ev, cz(c, U0, V), 0.0);
        if (!here)
            continue;
        eye = c->eu <= Uc + 1 && c->eu >= Uc && c->ev >= V && c->ev <= V + 1;
        if (eye) { /* holds the eye */
            double k = z[0] - z[1] - z[2] + z[3], ae = c->eu - Uc, be = c->ev - V;
            twist = dmax(twist, fabs(k));
            slope = dmax(slope, dmax(fabs(z[1] - z[0]), fabs(z[3] - z[2])) + dmax(fabs(z[2] - z[0]), fabs(z[3] - z[1])));
            if ((sw->bil || sw->tri) && sw->nes < 2) { /* starts_under_eye's */
                memcpy(sw->es[sw->nes].z, z, sizeof sw->es[0].z);
                sw->es[sw->nes].ae = ae;
                sw->es[sw->nes].be = be;
                sw->es_h = h;
                sw->nes++;
            }
            if (sw->bil && k != 0.0) {
                double ga = (z[1] - z[0]) + k * be, gb = (z[2] - z[0]) + k * ae;
                /* rays that enter the cell from the eye, and k m < 0 */
                double lo = be <= 0.0 ? 0.0 : -1.0, hi = be >= 1.0 ? 0.0 : 1.0;
                if (k > 0.0)
                    hi = dmin(hi, 0.0);
                else
                    lo = dmax(lo, 0.0);
                /* its peaks are real points unless the nearest, sqrt(h / |k|) away at |m| = 1,
                 * may be nearer than the tracer looks (near_u): then a bound only, in N */
                int real = h > 0.0 && sqrt(h / fabs(k)) > 2.0 * sw->near_u;
                if (hi > lo) {
                    if (!real)
                        swap_gn(sw);
                    eye_cell_bound(sw, ga, gb, fabs(k) * h, k, u0, hi > 0.0 ? 1.0 - be : be, lo, hi);
                    if (!real)
                        swap_gn(sw);
                }
            }
        }
        /* The bilinear cell that holds the eye needs no upper diagonal: along each ray q
         * peaks at its exit, an edge, or where eye_cell_bound bounds it. Its diagonal, up to
         * a quarter of the twist over the patch, passes by the eye: 0.06 cells east of Blanca
         * Peak's sample, 3.5 m over the eye 0.03 cells from it, it put N at 115 .. 0 over m
         * -1 .. 0.2 of the south cone, over every target there (176,377 casts, not 3,896). */
        if (!sw->lin && !(sw->bil && eye)) {
            double slack;
            if (sw->bil) /* the upper diagonal of a bilinear cell: a bound only */
                swap_gn(sw);
            if (upper_main(sw, z, 1.0, &slack))
                add_clipped(sw, uc, V - c->ev, z[0], u0, V + 1 - c->ev, z[3], sw->bil ? INFINITY : 0.0);
            else
                add_clipped(sw, u0, V - c->ev, z[1], uc, V + 1 - c->ev, z[2], sw->bil ? INFINITY : 0.0);
            if (sw->bil)
                swap_gn(sw);
        }
    }
    /* Every segment starts over the surface, where the tracer starts it (t = 2^-30), when
     * the eye is over it by more than the segment may fall below the ground there: at
     * horizontal distance w = 2^-30 u_T (u_T the target's) the ground has risen at most
     * slope w (|m| <= 1) and the segment fallen at most (ez - zmin) / u_T w (a target is no
     * lower than zmin), so by 2^-30 (slope u_T + ez - zmin); with 1e-9 of the eye's height
     * to spare for rounding. Before, the eye only had to clear the 1e-9: one 1e-7 m over a
     * steep slope had segments under the surface from their start (test_low_eye). */
    double fall = 0x1p-30 * (slope * (c->uhi - c->eu) + dmax(j->ez - j->v->grid->zmin, 0.0));
    sw->hidden_ok = h > 1e-9 * (1.0 + fabs(j->ez)) + fall + (sw->lin ? twist / 4.0 : 0.0);
    /* the linear surface's chord under the eye may be above it: then nothing is proved
     * without a look at each segment's start (visible_start) */
    sw->visible_ok = !sw->lin || sw->hidden_ok;
    sw->visible_start = !sw->visible_ok;
    merge_g(sw);
    sw->nmax = n_max(&sw->N);
}

/* ---- the targets ------------------------------------------------------------------ */

/* The segment to (U, V) cast, as td_viewshed does without the sweep. */
static void cast(sweep *sw, int32_t U, int32_t V)
{
    const td_vsweep_job *j = sw->job;
    const cone *c = &sw->c;
    int32_t i = c->ui * U + c->vi * V, jj = c->uj * U + c->vj * V;
    uint32_t steps = 0;
    int r = td_viewshed_cast(j->v, j->surface, j->method, j->ex, j->ey, j->ez, i, jj, j->target_height, &steps);
    sw->rays += r == 0 || r == 1;
    sw->steps += steps;
    sw->vis[vidx(c, j->north_first, U, V)] = r > 0;
}

/* The diagonal the segment to (U, V) crosses in its last strip, if it does not end at
 * (U, V) (column U buffered): raises *hi and *lo. */
static inline void last_cell(const sweep *sw, int32_t V, double u, double m, double hu, double *hi, double *lo)
{
    double z[4], slack, a = fabs(m), s = 0.0, h = NAN, q;
    /* the cell's diagonal first (its twist): the divisions only for the one that counts */
    if (m > 0.0 && !sw->lin && cellz(sw, sw->zcol[0], sw->zcol[1], V - 1, z) && !upper_is_main(sw, z)) {
        s = a / (1.0 + a);
        h = z[1] + (z[2] - z[1]) * (1.0 - a + a * s); /* from the south-west: (U, V-1)-(U-1, V) */
    } else if (m < 0.0 && !sw->lin && cellz(sw, sw->zcol[0], sw->zcol[1], V, z) && upper_is_main(sw, z)) {
        s = a / (1.0 + a);
        h = z[0] + (z[3] - z[0]) * s; /* from the north-west: the main diagonal (U-1, V)-(U, V+1) */
    }
    if (!isnan(h)) {
        slack = upper_slack(sw, z, u - 1.0);
        q = (h - sw->job->ez) / (u - 1.0 + s);
        *hi = dmax(*hi, q);
        if (u - 1.0 + s < hu)
            *lo = dmax(*lo, q - slack);
    }
}

/* Rows V0 .. V1 split at the eye's row: m < 0 below *Vm, m = 0 from *Vm to *Vp - 1 (ev a
 * row), m > 0 from *Vp. */
static inline void eye_rows(double ev, int32_t V0, int32_t V1, int32_t *Vm, int32_t *Vp)
{
    *Vm = (int32_t)dmin(dmax(ceil(ev), (double)V0), (double)V1 + 1.0);
    *Vp = *Vm + (*Vm <= V1 && *Vm == ev);
}

/* Whether the segment to (U, V) starts clearly above the surface where the tracer starts
 * it (by 2^-44 of the eye's height, 16 times what starts_under tolerates): then a real
 * surface point above it later proves it hidden, as for an eye above the ground (the
 * tracer meets a crossing before that point). For eyes hidden_ok does not cover: on the
 * ground, or under a linear cell's chord. */
static int starts_clear(const sweep *sw, int32_t U, int32_t V)
{
    const td_vsweep_job *j = sw->job;
    const cone *c = &sw->c;
    int32_t i = c->ui * U + c->vi * V, jj = c->uj * U + c->vj * V;
    td_ray r;
    return td_viewshed_ray(j->v->grid, j->surface, j->ex, j->ey, j->ez, i, jj, j->target_height, &r) == 0 &&
           td_viewshed_start_gap(j->v->grid, j->surface, &r) > 0x1p-44 * (1.0 + fabs(j->ez));
}

/* The highest q of a real point of the bilinear surface on the ray m in the strip between
 * columns U-1 and U (cone cells U-1..U): per cell the ray crosses there, the ends of its
 * run through it and the stationary point of q along it (z is quadratic along the ray,
 * so with w the distance q = A / w + B + C w: w = sqrt(A / C)), each evaluated on the
 * patch itself. Any of them is a real point; -inf when the ray crosses no cell there. */
static double strip_real_max(const sweep *sw, int32_t U, double m, double amax)
{
    const cone *c = &sw->c;
    double ez = sw->job->ez, best = -INFINITY, z[4], u0 = U - 1 - c->eu;
    double v0 = m * u0, v1 = m * (u0 + 1.0);
    int32_t Va = (int32_t)floor(dmin(v0, v1) + c->ev), Vb = (int32_t)floor(dmax(v0, v1) + c->ev);
    for (int32_t V = Va; V <= Vb && u0 > 0.0; V++) {
        double b0 = m * u0 - (V - c->ev), alo = 0.0, ahi = 1.0, k, Z0, Z1, Z2, A, cand[3];
        if (!cell(c, U - 1, V, z))
            continue;
        if (m > 0.0) { /* b = b0 + m a in [0, 1] */
            alo = dmax(alo, -b0 / m);
            ahi = dmin(ahi, (1.0 - b0) / m);
        } else if (m < 0.0) {
            alo = dmax(alo, (1.0 - b0) / m);
            ahi = dmin(ahi, -b0 / m);
        } else if (b0 < 0.0 || b0 > 1.0) {
            continue;
        }
        k = z[0] - z[1] - z[2] + z[3];
        Z0 = z[0] + (z[2] - z[0]) * b0;
        Z1 = (z[1] - z[0]) + (z[2] - z[0]) * m + k * b0;
        Z2 = k * m;
        A = Z2 * u0 * u0 - Z1 * u0 + Z0 - ez;
        ahi = dmin(ahi, amax);
        cand[0] = alo;
        cand[1] = ahi;
        cand[2] = Z2 < 0.0 && A < 0.0 ? sqrt(A / Z2) - u0 : alo;
        for (int i = 0; i < 3 && alo <= ahi; i++) {
            double a = dmin(dmax(cand[i], alo), ahi), b = b0 + m * a;
            double zz = z[0] + (z[1] - z[0]) * a + (z[2] - z[0]) * b + k * a * b;
            best = dmax(best, (zz - ez) / (u0 + a));
        }
    }
    return best;
}

/* A lower bound of the surface's q on the ray m from real points, for a target that p (F's
 * piece there) leaves undecided by its bilinear slack: strip_real_max in p's strip (U from
 * its umax), when p proves at all (a finite slack, no hole nearer). */
static double band_lo(const sweep *sw, const piece *p, double m, double hu)
{
    double lo = -INFINITY;
    if (p->slack > 0.0 && p->slack < INFINITY && p->umax < hu)
        lo = strip_real_max(sw, (int32_t)lround(p->umax + sw->c.eu), m, 1.0);
    return lo;
}

/* A lower bound of the surface's q on the ray m from real points of the target's own last
 * strip (cells U-1..U), for a bilinear target its last cell's upper diagonal leaves
 * undecided (the slope that faces away just before it): strip_real_max there, its points
 * at least VS_LAST_GAP of a cell short of the target (so the crossing they prove is far
 * inside the tracer's segment, which stops 2^-30 of it short of the target), when no hole
 * is nearer than them. */
static double last_real(const sweep *sw, int32_t U, double u, double m, double hu)
{
    return u - VS_LAST_GAP < hu ? strip_real_max(sw, U, m, 1.0 - VS_LAST_GAP) : -INFINITY;
}

/* What the targets of column U read, loaded once a column into a local (the compiler
 * reloads sw's fields after every byte written to vis: a char may alias them). Arrays
 * offset by the rows' origin. */
typedef struct tgt_cols {
    const double *mc, *zc, *qc, *qp, *zp;
    const double *fh;    /* fhi (col_pass), valid with pass */
    const int *kc;       /* valid with pass */
    const piece *Fp, *Np;
    const double *hole_u; /* NULL without holes */
    uint8_t *vis;         /* sample (U, V)'s byte: vis[V * vstride] */
    ptrdiff_t vstride;
    double u, ez, th;     /* th: the target height */
    int32_t vlo, vhi;
    int pass, hidden_ok, visible_ok, visible_start, bil, lin;
    int nn, hint_n;       /* N's pieces, the search's hint */
    double nmax;          /* N's maximum */
    double ea;            /* the visible proofs' absolute eps (ground_eps) */
    double em;            /* 2^-13 / u: end_clear's margin over 1 + |z| */
    int tri, anti;
} tgt_cols;

/* The absolute eps a visible proof needs in column u: VS_EPS_ABS, and with the eye on the
 * ground (not hidden_ok) enough that the segment clears the surface where the tracer
 * starts it (t = 2^-30) by more than its rounding. There the segment's height over the
 * eye's cell is (q - s) w at horizontal distance w, s the cell's slope along the ray,
 * which hi bounds (the eye's strip is in F and N), so q > hi + 2^-13 (1 + |ez|) / u puts
 * it 2^-43 (1 + |ez|) over the surface at w = 2^-30 u: starts_clear's measure, twice
 * (the computed gap is off by a few of ez's ulps, 2^-52 |ez| each). A target in between
 * is proved visible only when starts_clear says so: its segment may leave the eye along
 * the surface (a target in the plane of the eye's triangle: the tracer's start then
 * decides by rounding, and calls it a touch). Found by test_saddle. */
static inline double ground_eps(const sweep *sw, double u)
{
    return VS_EPS_ABS + (sw->hidden_ok ? 0.0 : 0x1p-13 * (1.0 + fabs(sw->job->ez)) / u);
}

/* Column U's context for target(). */
static void tgt_cols_init(sweep *sw, int32_t U, tgt_cols *t)
{
    const cone *c = &sw->c;
    t->mc = sw->mcol[1] - c->vlo;
    t->zc = sw->zcol[1] - c->vlo;
    t->qc = sw->qcol[1] - c->vlo;
    t->qp = sw->qcol[0] - c->vlo;
    t->zp = sw->zcol[0] - c->vlo;
    t->kc = sw->kcol - c->vlo;
    t->fh = sw->fhi - c->vlo;
    t->Fp = sw->F.p;
    t->Np = sw->N.p;
    t->nn = sw->N.n;
    t->nmax = sw->nmax;
    t->hint_n = 0;
    t->hole_u = sw->holes ? sw->hole_u : NULL;
    t->vis = sw->vis + vidx(c, sw->job->north_first, U, 0);
    t->vstride = c->vi == 0 ? (sw->job->north_first ? -(ptrdiff_t)c->g->w : (ptrdiff_t)c->g->w) : 1;
    t->u = U - c->eu;
    t->ez = sw->job->ez;
    t->th = sw->job->target_height;
    t->vlo = c->vlo;
    t->vhi = c->vhi;
    t->pass = sw->pass_ok;
    t->hidden_ok = sw->hidden_ok;
    t->visible_ok = sw->visible_ok;
    t->visible_start = sw->visible_start;
    t->bil = sw->bil;
    t->lin = sw->lin;
    t->ea = ground_eps(sw, t->u);
    t->em = 0x1p-13 / t->u;
    t->tri = sw->tri;
    t->anti = c->anti;
}

/* Whether the segment to ground target (U, V) (no target height) arrives over the
 * surface by more than the tracer's rounding where the tracer ends it, 2^-30 of the
 * segment short of the target. Both meet at the target, so there the segment is over the
 * surface by (z' - q) d at a distance d before it (d = 2^-30 u in cells), z' the slope
 * of the surface into the target along the ray (per cell of u, from the last cell: the
 * bilinear patch's or the plane's at that corner, the linear surface's chord through the
 * cell), q the segment's. A proof that the segment clears everything nearer by eps
 * bounds its distance from the surface at the last cell's diagonal, not at its end: where
 * the surface rises into the target along the line of sight (z' = q), the tracer's end
 * decides by rounding. So a visible proof also needs z' - q >= 2^-13 (1 + |z|) / u, 2^-43
 * (1 + |z|) at the tracer's end: twice starts_clear's measure. Found by a fuzzer with
 * curvature on exact terrain (test_exact_terrains). A void corner: no surface there, 1. */
static inline int end_clear(const tgt_cols *t, int32_t V, double m, double q)
{
    const double *zp = t->zp, *zc = t->zc;
    double zt = zc[V], zs;
    if (t->th > 0.0)
        zs = INFINITY; /* over the ground at its end by th */
    else if (m > 0.0) /* the last cell V-1: (U-1, V-1) z0, (U, V-1) z1, (U-1, V) z2, (U, V) z3 */
        zs = V - 1 < t->vlo ? INFINITY
             : t->lin      ? zt - (zp[V] + (zp[V - 1] - zp[V]) * m)
                           : (zt - zp[V]) + m * (t->tri && !t->anti ? zp[V] - zp[V - 1] : zt - zc[V - 1]);
    else if (m < 0.0) /* the last cell V: (U-1, V) z0, (U, V) z1, (U-1, V+1) z2, (U, V+1) z3 */
        zs = V + 1 > t->vhi ? INFINITY
             : t->lin      ? zt - (zp[V] + (zp[V + 1] - zp[V]) * -m)
                           : (zt - zp[V]) + m * (t->tri && t->anti ? zp[V + 1] - zp[V] : zc[V + 1] - zt);
    else /* along the row's edge */
        zs = zt - zp[V];
    return !(zs - q < t->em * (1.0 + fabs(zt)));
}

/* An upper bound of what last_cell may add to hi for target (U, V): its diagonal's point
 * lies on the edge between two samples, so its q is at most theirs (+inf when a sample is
 * off the grid: then last_cell decides). side: the sign of m_V (V against the eye's row). */
static inline double diag_bound(const tgt_cols *t, int32_t V, int side)
{
    double b = -INFINITY;
    if (t->lin || side == 0)
        b = -INFINITY;
    else if (side > 0)
        b = V - 1 >= t->vlo ? dmax(t->qc[V - 1], t->qp[V]) : INFINITY;
    else
        b = V + 1 <= t->vhi ? dmax(t->qp[V], t->qc[V + 1]) : INFINITY;
    return isnan(b) ? INFINITY : b;
}

/* target()'s visible decision when it needs neither N nor the bilinear band: q above F
 * at m_V and the last cell's diagonal (fhi raised by last_diags), and above N's maximum
 * (so N is not looked at), each by eps as target() decides. 0: target() decides (so
 * also where q clears only the diagonal's ends, diag_bound, which target() then finds).
 * Columns with the column pass, no target height; ea: the absolute eps (t->ea, VS_EPS_ABS
 * where hidden_ok, which leaves it that constant). */
static inline int quick_visible(const tgt_cols *t, int32_t V, double ea)
{
    double q = t->qc[V], eps = ea + VS_EPS_REL * fabs(q);
    return q > t->fh[V] + eps && q > t->nmax + 2.0 * eps;
}

/* Four doubles for last_diags (the AVX2 clone's registers; two SSE2 ones in the other) */
typedef double vd4 __attribute__((vector_size(32)));
typedef long long vl4 __attribute__((vector_size(32)));
#define LD4(p) (*(const vd4u *)(p)) /* an unaligned load (no vd4 returned: the SSE2 clone's ABI) */
typedef double vd4u __attribute__((vector_size(32), aligned(8), may_alias));

/* The constants of last_diags' lanes */
typedef struct diag_k {
    vd4 ez, u1, kmul, kadd, ea, er;
    vd4 em, inf;      /* end_clear's 2^-13 / u; +inf */
    int alt_p, alt_m; /* the triangle's end slope across its other plane (end_clear), m > 0, m < 0 */
} diag_k;

/* last_diags for rows V .. V+3 (the first n), on one side of the eye's row (side a
 * constant where it is inlined): m < 0, cell V's main diagonal (U-1, V)-(U, V+1); m > 0,
 * cell V-1's other one (U, V-1)-(U-1, V). last_cell's expressions lane by lane. */
static inline __attribute__((always_inline)) void diag_quad(const double *zp, const double *zc, const double *mc,
                                                            const double *qc, double *fh, const diag_k *d, int32_t V,
                                                            int n, int side)
{
    const vd4 one = {1.0, 1.0, 1.0, 1.0}, zero = {0.0, 0.0, 0.0, 0.0};
    const vl4 absm = {INT64_MAX, INT64_MAX, INT64_MAX, INT64_MAX};
    int32_t W = side < 0 ? V : V - 1; /* the cell's lower row */
    vd4 z0 = LD4(zp + W), z1 = LD4(zc + W), z2 = LD4(zp + W + 1), z3 = LD4(zc + W + 1), h0 = LD4(fh + V);
    /* z0 (U-1, W), z1 (U, W), z2 (U-1, W+1), z3 (U, W+1): the target is z1 (m < 0) or z3 */
    vd4 a = (vd4)((vl4)LD4(mc + V) & absm), s = a / (one + a), q;
    /* the twist k (the main diagonal upper where k >= 0), or for the triangle +-1 (main in
     * two cones): k * 1 + 0 compares as k does; NaN sum: a void corner (cellz) */
    vd4 k = (z0 - z1 - z2 + z3) * d->kmul + d->kadd, sum = z0 + z1 + z2 + z3;
    vl4 main = (vl4)(k >= zero), take;
    if (side < 0)
        q = (z0 + (z3 - z0) * s - d->ez) / (d->u1 + s);
    else
        q = (z1 + (z2 - z1) * (one - a + a * s) - d->ez) / (d->u1 + s);
    take = (side < 0 ? main : ~main) & (vl4)(sum == sum) & (vl4)(q > h0);
    q = (vd4)(((vl4)q & take) | ((vl4)h0 & ~take));
    /* end_clear's expressions lane by lane (m = a or -a): +inf where the segment's end is
     * not clear of the surface (quick_visible then fails, and target() decides) */
    vd4 zs, zt = side < 0 ? z1 : z3, qt = LD4(qc + V);
    if (side < 0)
        zs = (z1 - z0) + -a * (d->alt_m ? z2 - z0 : z3 - z1);
    else
        zs = (z3 - z2) + a * (d->alt_p ? z2 - z0 : z3 - z1);
    vl4 bad = (vl4)(zs - qt < d->em * (one + (vd4)((vl4)zt & absm)));
    q = (vd4)(((vl4)d->inf & bad) | ((vl4)q & ~bad));
    if (n > 3)
        memcpy(fh + V, &q, sizeof q);
    else
        for (int i = 0; i < n; i++)
            fh[V + i] = q[i];
}

/* Whether any of the VS_DIAG targets from V has its q above fhi by eps (quick_visible's
 * first test): only those may need their last cell's diagonal. */
static inline __attribute__((always_inline)) int visible_any(const double *qc, const double *fh, const diag_k *d,
                                                             int32_t V)
{
    const vl4 absm = {INT64_MAX, INT64_MAX, INT64_MAX, INT64_MAX};
    vl4 c = {0, 0, 0, 0};
    for (int i = 0; i < VS_DIAG; i += 4) {
        vd4 q = LD4(qc + V + i);
        c |= (vl4)(q > LD4(fh + V + i) + (d->ea + d->er * (vd4)((vl4)q & absm)));
    }
    return (c[0] | c[1] | c[2] | c[3]) != 0;
}

/* last_diags' rows Va .. Vb - 1 on one side of the eye's row, VS_DIAG at a time: those past
 * Vb in the last ones are read (rows of the buffers) but not stored. */
static inline __attribute__((always_inline)) void diag_run(const double *zp, const double *zc, const double *mc,
                                                           const double *qc, double *fh, const diag_k *d,
                                                           int32_t Va, int32_t Vb, int side)
{
    for (int32_t V = Va; V < Vb; V += VS_DIAG) {
        if (!visible_any(qc, fh, d, V))
            continue;
        for (int32_t i = 0; i < VS_DIAG && V + i < Vb; i += 4)
            diag_quad(zp, zc, mc, qc, fh, d, V + i, Vb - (V + i) < 4 ? Vb - (V + i) : 4, side);
    }
}

/* fhi[V] raised to last_cell's value for rows V0 .. V1 of column U (the q where the
 * segment to (U, V) crosses its last cell's diagonal, when that diagonal is the cell's
 * upper one and does not end at (U, V); nothing for a cell with a void corner), four rows
 * to a vector, each lane last_cell's expressions (the same bits), for the rows that may be
 * visible: quick_visible then tests one bound. Before, quick_visible called last_cell for
 * three quarters of the visible targets, a branch on the twist's sign (a coin toss) and
 * two divisions each: trinidad from Blanca Peak 903.0 -> 820.4 M instructions (840.4
 * with two rows a vector; docs/viewshed.md "Speed"; the TD_VSWEEP_DEBUG build checks
 * each row against last_cell). */
TD_ROW_CLONES static void last_diags(sweep *sw, const tgt_cols *t, int32_t U, int32_t V0, int32_t V1)
{
    const cone *c = &sw->c;
    const int32_t o = c->vlo;
    const double *zp = sw->zcol[0] - o, *zc = sw->zcol[1] - o, *mc = sw->mcol[1] - o, *qc = sw->qcol[1] - o;
    double *fh = sw->fhi - o;
    const double ez = sw->job->ez, u1 = U - c->eu - 1.0, km = sw->bil ? 1.0 : 0.0;
    const double ka = sw->bil ? 0.0 : (c->anti ? -1.0 : 1.0);
    const diag_k d = {{ez, ez, ez, ez},
                      {u1, u1, u1, u1},
                      {km, km, km, km},
                      {ka, ka, ka, ka},
                      {VS_EPS_ABS, VS_EPS_ABS, VS_EPS_ABS, VS_EPS_ABS},
                      {VS_EPS_REL, VS_EPS_REL, VS_EPS_REL, VS_EPS_REL},
                      {t->em, t->em, t->em, t->em},
                      {INFINITY, INFINITY, INFINITY, INFINITY},
                      sw->tri && !c->anti,
                      sw->tri && c->anti};
    int32_t Vm, Vp;
    eye_rows(c->ev, V0, V1, &Vm, &Vp);
    Vm = Vm < c->vhi ? Vm : c->vhi; /* the cells on the grid (last_cell's cellz) */
    Vp = Vp > o + 1 ? Vp : o + 1;
#ifdef TD_VSWEEP_DEBUG /* each row that may be visible checked against last_cell */
    double *was = malloc((size_t)(V1 - V0 + 1) * sizeof *was);
    for (int32_t V = V0; V <= V1 && was; V++)
        was[V - V0] = fh[V];
#endif
    diag_run(zp, zc, mc, qc, fh, &d, V0, Vm, -1);
    diag_run(zp, zc, mc, qc, fh, &d, Vp, V1 + 1, 1);
    for (int32_t V = Vm > V0 ? Vm : V0; V < Vp && V <= V1; V++) /* the eye's row (m = 0) */
        if (!end_clear(t, V, mc[V], qc[V]))
            fh[V] = INFINITY;
#ifdef TD_VSWEEP_DEBUG
    for (int32_t V = V0; V <= V1 && was; V++) {
        double hi = was[V - V0], lo = -INFINITY, q = qc[V];
        last_cell(sw, V, U - c->eu, mc[V], INFINITY, &hi, &lo);
        if (!end_clear(t, V, mc[V], q))
            hi = INFINITY;
        if ((q > was[V - V0] + VS_EPS_ABS + VS_EPS_REL * fabs(q) && fh[V] != hi) ||
            (fh[V] != was[V - V0] && fh[V] != hi)) {
            fprintf(stderr, "last_diags: U %d V %d: %.17g, last_cell %.17g\n", U, V, fh[V], hi);
            abort();
        }
    }
    free(was);
#endif
}

/* The segment to a target at u, m, q starts under the surface, as the cast's
 * td_viewshed_starts_under finds it (and so blocks it without a trace), by far more than
 * either side's rounding. Its start, 2^-30 of it, is w = 2^-30 u cells from the eye, at
 * a = ae + w, b = be + m w in a cell that holds the eye (bilinear or triangle; not within
 * 2^-40 of the cell's sides, nor of the diagonal unless the eye is on it, so that the
 * surface there is the eye's own patch or plane: height ground + s(m) w + k m w^2). The
 * segment is over the surface there by h + (q - s(m)) w - k m w^2, which must be under
 * -2^-38 (1 + |ez|) (1024 times the cast's tolerance, 2^-48 (1 + |ez|)) less the rounding
 * of q - s. An eye on the ground off its sample: the segments that leave it uphill (from
 * Blanca Peak 0.3 cells east and 0.2 south, 735,337 of them) were cast, each stopped at
 * once by that test. */
static int starts_under_eye(const sweep *sw, double u, double m, double q)
{
    const double tiny = 0x1p-40, w = 0x1p-30 * u, ez = fabs(sw->job->ez);
    int under = 0;
    for (int e = 0; e < sw->nes && !under; e++) {
        const double *z = sw->es[e].z;
        double ae = sw->es[e].ae, be = sw->es[e].be, a = ae + w, b = be + m * w, k = 0.0, ga, gb, s, gap;
        int in = a < 1.0 - tiny && b > tiny && b < 1.0 - tiny;
        if (sw->tri) { /* the start's triangle, the eye's too: anti a + b < 1 (z0 z1 z2) or not, else a > b (z0 z1 z3) or not */
            double d = sw->c.anti ? a + b - 1.0 : a - b, de = sw->c.anti ? ae + be - 1.0 : ae - be;
            int first = sw->c.anti ? d < 0.0 : d > 0.0;
            in = in && fabs(d) > tiny && (de == 0.0 || (de > 0.0) == (d > 0.0));
            ga = first ? z[1] - z[0] : z[3] - z[2];
            gb = first == !sw->c.anti ? z[3] - z[1] : z[2] - z[0];
        } else { /* the bilinear patch: its slope along the ray at the eye, as near_strip's */
            k = z[0] - z[1] - z[2] + z[3];
            ga = (z[1] - z[0]) + k * be;
            gb = (z[2] - z[0]) + k * ae;
        }
        s = ga + gb * m;
        gap = sw->es_h + (q - s) * w - k * m * w * w;
        under = in && gap < -0x1p-38 * (1.0 + ez) - 1e-12 * (fabs(q) + fabs(s)) * w;
    }
    return under;
}

/* Decides target (U, V) of column U (not a void) against F, or casts it. */
static void target(sweep *sw, tgt_cols *t, int32_t U, int32_t V)
{
    const piece *Fp = t->Fp;
    double u = t->u, m = t->mc[V], zt = t->zc[V], q, hi, lo, eps, hu;
    int k;
    q = t->th > 0.0 ? (zt + t->th - t->ez) / u : t->qc[V];
    k = t->pass ? t->kc[V] : find(&sw->F, m, &sw->hint_q);
    hu = t->hole_u ? t->hole_u[bin_of(m)] : INFINITY;
    hi = pval(&Fp[k], m);
    lo = Fp[k].umax < hu ? hi - Fp[k].slack : -INFINITY;
    if (k > 0 && Fp[k].m == m) { /* on a break: the piece ending here holds m too */
        double v = pval(&Fp[k - 1], m);
        if (Fp[k - 1].umax < hu)
            lo = dmax(lo, v - Fp[k - 1].slack);
    }
    hi = f_near_max(Fp, k, m, hi);
    eps = VS_EPS_ABS + VS_EPS_REL * fabs(q);
    if (q < lo - eps && t->hidden_ok) /* proved hidden already: the rest only raises lo */
        goto decide;
    /* N counts only where it may reach q: above its maximum (with eps to spare for the
     * rounding of a piece's value between its ends), hi decides alone */
    if (q <= t->nmax + 2.0 * eps) {
        int kn = find_in(t->Np, t->nn, m, &t->hint_n);
        hi = f_near_max(t->Np, kn, m, dmax(hi, pval(&t->Np[kn], m)));
    }
    if (t->th > 0.0)
        hi = dmax(hi, (zt - t->ez) / u);
    /* clear of everything nearer and of its last cell's diagonal's ends: visible without it */
    if (!(t->visible_ok && q > dmax(hi, diag_bound(t, V, (m > 0.0) - (m < 0.0))) + eps))
        last_cell(sw, V, u, m, hu, &hi, &lo);
    /* in the bilinear slack of its piece: real points of that strip on the ray may prove it hidden */
    if (t->bil && q >= lo - eps && !(q > hi + eps && t->visible_ok))
        lo = dmax(lo, band_lo(sw, &Fp[k], m, hu));
    /* above everything nearer but not clear of its last cell: real points there */
    if (t->bil && q >= lo - eps && !(q > hi + eps && t->visible_ok))
        lo = dmax(lo, last_real(sw, U, u, m, hu));
decide:;
    /* visible: clear of everything nearer, and with the eye on the ground of its start
     * (ground_eps). On the linear surface with a chord under the eye that may be over it
     * (visible_start), a segment that starts over it (starts_clear) stays over the eye's
     * cell's chord along its line (both linear in u, the segment over it at the start and,
     * above the cell's edges, at its exit), and the other cells' chords peak in q at their
     * edges (in F): from Blanca Peak's sample, 2 m up, 1,496,730 casts before, 202 after. */
    int vis = (t->visible_ok || t->visible_start) && q > hi + eps &&
              ((t->visible_ok && q > hi + t->ea + VS_EPS_REL * fabs(q)) || starts_clear(sw, U, V)) &&
              end_clear(t, V, m, q);
#ifdef TD_VSWEEP_DEBUG /* every proof checked against the cast */
    if (vis || (q < lo - eps && (t->hidden_ok || starts_clear(sw, U, V))) ||
        (!t->hidden_ok && starts_under_eye(sw, u, m, q))) {
        const td_vsweep_job *j = sw->job;
        const cone *c = &sw->c;
        uint32_t st = 0;
        int32_t i = c->ui * U + c->vi * V, jj = c->uj * U + c->vj * V;
        int r = td_viewshed_cast(j->v, j->surface, j->method, j->ex, j->ey, j->ez, i, jj, j->target_height, &st);
        if ((r > 0) != vis)
            fprintf(stderr, "MISMATCH U %d V %d (i %d j %d) u %g m %g q %.9g hi %.9g lo %.9g cast %d F piece %d/%d\n",
                    U, V, i, jj, u, m, q, hi, lo, r, k, sw->F.n);
    }
#endif
    if (vis) {
        t->vis[V * t->vstride] = 1;
        sw->swept++;
    } else if ((q < lo - eps && (t->hidden_ok || starts_clear(sw, U, V))) ||
               (!t->hidden_ok && starts_under_eye(sw, u, m, q))) {
        t->vis[V * t->vstride] = 0;
        sw->swept++;
    } else {
        cast(sw, U, V);
    }
}

/* Column U's targets V0 .. V1 (the cone's rows) in the common case: every one owned (no
 * max_distance), both quick decisions on (sweep_cone's quick and quickv); voids are left
 * as they are (until 2026-12-02 a grid with any void took sweep_cone's loop: picos's
 * frame of voids, 108.7 -> 103.1 M). The
 * same tests as sweep_cone's loop, in that order and with the same expressions (so the
 * same bits), in a function of its own: inlined into cone_worker with everything else,
 * the loop kept its pointers and flags on the stack (about 34 instructions a target for
 * the loop, owned()'s and the void test and the hidden test, callgrind). */
static void targets_plain(sweep *sw, tgt_cols *t, int32_t U, int32_t V0, int32_t V1)
{
    const tgt_cols lt = *t; /* a copy quick_visible reads: its address is not taken elsewhere,
                               so the bytes written to vis are known not to change it */
    const double *qc = lt.qc, *fl = sw->flo - lt.vlo;
    uint8_t *vis = lt.vis;
    const ptrdiff_t vs = lt.vstride;
    uint64_t n = 0;
    for (int32_t V = V0; V <= V1; V++) {
        double q = qc[V];
        if (q < fl[V] - (VS_EPS_ABS + VS_EPS_REL * fabs(q))) {
            vis[V * vs] = 0;
            n++;
        } else if (quick_visible(&lt, V, VS_EPS_ABS)) { /* quick: hidden_ok, so ea is VS_EPS_ABS */
#ifdef TD_VSWEEP_DEBUG /* the proof checked against the cast, as target()'s */
            const td_vsweep_job *j = sw->job;
            const cone *c = &sw->c;
            uint32_t st = 0;
            if (td_viewshed_cast(j->v, j->surface, j->method, j->ex, j->ey, j->ez, c->ui * U + c->vi * V,
                                 c->uj * U + c->vj * V, j->target_height, &st) <= 0)
                fprintf(stderr, "MISMATCH quick_visible U %d V %d\n", U, V);
#endif
            vis[V * vs] = 1;
            n++;
        } else if (!isnan(lt.zc[V])) { /* a void's q is NaN: it fails both tests above */
            target(sw, t, U, V);
        }
    }
    sw->swept += n;
}

/* Whether a sample dv rows from the eye's is in the cone at distance u (strict: north and
 * south, whose diagonals belong to east and west). */
static inline int in_cone(double dv, double u, int strict)
{
    dv = fabs(dv);
    return strict ? dv < u : dv <= u;
}

/* Whether sample (U, V) belongs to this cone and is within max_distance. */
static int owned(const sweep *sw, int32_t U, int32_t V, double u)
{
    const cone *c = &sw->c;
    const td_grid *g = c->g;
    double dx, dy;
    int32_t i, j;
    if (!in_cone(V - c->ev, u, c->strict))
        return 0;
    if (sw->job->maxd2 == INFINITY)
        return 1;
    i = c->ui * U + c->vi * V;
    j = c->uj * U + c->vj * V;
    dx = i * g->sx - sw->job->ex;
    dy = j * g->sy - sw->job->ey;
    return dx * dx + dy * dy <= sw->job->maxd2;
}

static void sweep_cone(sweep *sw)
{
    const cone *c = &sw->c;
    const double ev = c->ev;
    const int strict = c->strict, nomax = sw->job->maxd2 == INFINITY, holes = sw->holes;
    const double *fl = sw->flo - c->vlo;
    int quick, quickv;
    tgt_cols t;
    int32_t U0 = (int32_t)floor(c->eu) + 1; /* the first column east of the eye */
    pv_clear(&sw->F);
    for (int b = 0; b < VS_BINS; b++)
        sw->hole_u[b] = INFINITY;
    if (U0 <= c->uhi) {
        near_strip(sw, U0);
        sw->quick = sw->hidden_ok && !(sw->job->target_height > 0.0);
        load_next(sw, U0 - 2);
        load_next(sw, U0 - 1);
    }
    for (int32_t U = U0; U <= c->uhi && !sw->oom; U++) {
        double u = U - c->eu;
        int32_t V0 = (int32_t)dmax(floor(c->ev - u) - 1.0, (double)c->vlo);
        int32_t V1 = (int32_t)dmin(ceil(c->ev + u) + 1.0, (double)c->vhi);
        if (sw->job->cancel && atomic_load_explicit(sw->job->cancel, memory_order_relaxed))
            break;
        load_next(sw, U);
        col_pass(sw, U, V0, V1);
        sw->hint_q = 0;
        tgt_cols_init(sw, U, &t);
        quick = sw->quick && sw->pass_ok;
        quickv = sw->visible_ok && !(sw->job->target_height > 0.0) && sw->pass_ok && U > U0 + 1;
        /* the cone's rows (|V - ev| within u: an interval, found from its ends), then per
         * row owned()'s distance test and the void test when there are any */
        while (V0 <= V1 && !in_cone(V0 - ev, u, strict))
            V0++;
        while (V1 >= V0 && !in_cone(V1 - ev, u, strict))
            V1--;
        if (quickv && !sw->lin)
            last_diags(sw, &t, U, V0, V1);
        else if (quickv) /* the linear surface: no diagonals, the targets' ends (end_clear) */
            for (int32_t V = V0; V <= V1; V++)
                if (!end_clear(&t, V, t.mc[V], t.qc[V]))
                    sw->fhi[V - c->vlo] = INFINITY;
        if (nomax && quick && quickv) {
            targets_plain(sw, &t, U, V0, V1);
            V1 = V0 - 1; /* done */
        }
        for (int32_t V = V0; V <= V1; V++) {
            if ((!nomax && !owned(sw, U, V, u)) || (holes && isnan(t.zc[V])))
                continue;
            /* target()'s first test without its call: hidden under F's piece's lo (on a
             * break target() takes the higher of two: this lo is at most its) */
            if (quick && t.qc[V] < fl[V] - (VS_EPS_ABS + VS_EPS_REL * fabs(t.qc[V]))) {
                t.vis[V * t.vstride] = 0;
                sw->swept++;
                continue;
            }
            if (quickv && quick_visible(&t, V, t.ea)) {
#ifdef TD_VSWEEP_DEBUG /* the proof checked against the cast, as target()'s */
                uint32_t st = 0;
                const td_vsweep_job *j = sw->job;
                if (td_viewshed_cast(j->v, j->surface, j->method, j->ex, j->ey, j->ez, c->ui * U + c->vi * V,
                                     c->uj * U + c->vj * V, j->target_height, &st) <= 0)
                    fprintf(stderr, "MISMATCH quick_visible U %d V %d\n", U, V);
#endif
                t.vis[V * t.vstride] = 1;
                sw->swept++;
                continue;
            }
            if (U <= U0 + 1) /* the first two columns: cast */
                cast(sw, U, V);
            else
                target(sw, &t, U, V);
        }
        add_column(sw, U, U > U0);
    }
}

/* ---- the four cones across threads ---------------------------------------------------- */

typedef struct cone_task {
    const td_vsweep_job *job;
    uint8_t *vis;
    atomic_int next;
    sweep sw[4];
} cone_task;

/* The cones this thread takes, one after the other, on one set of buffers: the column
 * buffers sized for the longer side, and the envelope's lists handed from a cone to the
 * next (fresh pages cost: allocated a cone at a time they were a quarter of the page
 * faults of trinidad's whole command, docs/viewshed.md "Speed"). */
/* A cone worker's scratch, one buffer (td_bigalloc_scratch: one huge page's fault where
 * its 4 KiB pages and the lists' growth by realloc faulted in hundreds): the lists' first
 * pieces (F, C and T VS_LIST_ROWS a row of the grid's longer side, G and N one; a list
 * that outgrows its slice moves to malloc, pv_reserve; trinidad from Blanca Peak reached
 * 3.4 (F, C) and 0.2 (T) a row, picos from its centre 5.7 (F, C, T); the unit tests' small
 * grids outgrow theirs thousands of times), then the columns' doubles, the kcol ints, the
 * panel's floats and the colok bytes. */
#define VS_LIST_ROWS 6
enum { VS_LIST_EXTRA = 16 };

typedef struct scratch {
    void *buf;
    piece *list[5]; /* F, G, T, N, C */
    int cap[5];
    double *zb;
    int *kb;
    float *panel;
    uint8_t *ob;
} scratch;

static int scratch_init(scratch *s, size_t nmax)
{
    static const int rows[5] = {VS_LIST_ROWS, 1, VS_LIST_ROWS, 1, VS_LIST_ROWS};
    size_t at[5], n = 0, nzb = 15 * nmax + VS_DIAG, zb, kb, panel, ob;
    memset(s, 0, sizeof *s);
    if (nmax > (size_t)1 << 24) /* past any grid a cone's rows make (td_grid's limits) */
        return 0;
    for (int i = 0; i < 5; i++) {
        s->cap[i] = rows[i] * (int)nmax + VS_LIST_EXTRA;
        at[i] = n;
        n += (size_t)s->cap[i] * sizeof(piece);
    }
    zb = n;
    n += nzb * sizeof(double);
    kb = n;
    n += nmax * sizeof(int);
    panel = n;
    n += (size_t)VS_PANEL * nmax * sizeof(float);
    ob = n;
    n += nmax;
    if (!(s->buf = td_bigalloc_scratch(n)))
        return 0;
    for (int i = 0; i < 5; i++)
        s->list[i] = (piece *)(void *)((char *)s->buf + at[i]);
    s->zb = (double *)(void *)((char *)s->buf + zb);
    s->kb = (int *)(void *)((char *)s->buf + kb);
    s->panel = (float *)(void *)((char *)s->buf + panel);
    s->ob = (uint8_t *)s->buf + ob;
    /* zeroed: last_diags' candidate test reads up to VS_DIAG - 1 rows past a column's last
       (never stored), which would otherwise be bytes never written */
    memset(s->zb, 0, nzb * sizeof(double));
    return 1;
}

/* The worker's cones, one after another; each takes the lists of the one before (their
 * pieces are cleared by sweep_cone and near_strip), the first the scratch's. */
static void *cone_worker(void *arg)
{
    cone_task *t = arg;
    const td_grid *g = t->job->v->grid;
    size_t nmax = (size_t)(g->w > g->h ? g->w : g->h);
    scratch s;
    int ok = scratch_init(&s, nmax);
    sweep *prev = NULL;
    for (;;) {
        int k = atomic_fetch_add_explicit(&t->next, 1, memory_order_relaxed);
        sweep *sw;
        if (k >= 4)
            break;
        sw = &t->sw[k];
        size_t nv = (size_t)(sw->c.vhi - sw->c.vlo + 1);
        pvec *to[5] = {&sw->F, &sw->G, &sw->T, &sw->N, &sw->C};
        for (int i = 0; i < 5; i++) {
            if (prev) {
                pvec *from[5] = {&prev->F, &prev->G, &prev->T, &prev->N, &prev->C};
                *to[i] = *from[i];
                *from[i] = (pvec){NULL, 0, 0, 0};
            } else if (ok) {
                *to[i] = (pvec){s.list[i], 0, s.cap[i], 0};
            }
        }
        sw->panel = sw->c.vi == 0 ? s.panel : NULL;
        if (ok && pv_reserve(sw, &sw->F, 16) && pv_reserve(sw, &sw->G, 16) && pv_reserve(sw, &sw->T, 16) &&
            pv_reserve(sw, &sw->N, 16) && pv_reserve(sw, &sw->C, 16)) {
            for (size_t q = 0; q < 15 * nv; q++)
                s.zb[q] = NAN;
            memset(s.ob, 0, nv);
            for (int b = 0; b < 3; b++) {
                sw->zcol[b] = s.zb + (size_t)b * nv;
                sw->mcol[b] = s.zb + (size_t)(3 + b) * nv;
                sw->qcol[b] = s.zb + (size_t)(6 + b) * nv;
            }
            sw->fmin = s.zb + 9 * nv;
            sw->lcol = s.zb + 10 * nv;
            sw->cslope = s.zb + 11 * nv;
            sw->fmax = s.zb + 12 * nv;
            sw->flo = s.zb + 13 * nv;
            sw->fhi = s.zb + 14 * nv;
            sw->kcol = s.kb;
            sw->colok = s.ob;
            sweep_cone(sw);
        } else {
            sw->oom = 1;
        }
        sw->panel = NULL;
        prev = sw;
    }
    if (prev) { /* the lists the last cone holds: the malloc'ed ones freed, none left pointing into s */
        pvec *last[5] = {&prev->F, &prev->G, &prev->T, &prev->N, &prev->C};
        for (int i = 0; i < 5; i++) {
            if (last[i]->own)
                free(last[i]->p);
            *last[i] = (pvec){NULL, 0, 0, 0};
        }
    }
    free(s.buf);
    return NULL;
}

td_status td_vsweep(const td_vsweep_job *job, uint8_t *vis, td_vsweep_stats *st, td_err *err)
{
    const td_grid *g = job->v->grid;
    /* 128 KiB (each cone's hole_u): zeroed fresh 4 KiB pages cost 32 faults */
    cone_task *t = td_bigalloc_scratch(sizeof *t);
    pthread_t th[3];
    int n = job->threads < 1 ? 1 : (job->threads > 4 ? 4 : job->threads), started = 0, oom = 0;
    double eu = job->ex / g->sx, ev = job->ey / g->sy;
    td_status rc = TD_OK;
    memset(st, 0, sizeof *st);
    if (!t) {
        rc = td_err_set(err, TD_ENOMEM, "viewshed: out of memory");
        goto out;
    }
    memset(t, 0, sizeof *t);
    t->job = job;
    t->vis = vis;
    atomic_init(&t->next, 0);
    for (int k = 0; k < 4; k++) {
        sweep *sw = &t->sw[k];
        sw->job = job;
        sw->vis = vis;
        sw->tri = job->surface == TD_SURFACE_TRIANGLE;
        sw->bil = job->surface == TD_SURFACE_BILINEAR;
        sw->lin = job->surface == TD_SURFACE_LINEAR;
        sw->holes = g->voids > 0;
        cone_init(&sw->c, g, k, eu, ev);
    }
    /* the sample under the eye, if there is one, belongs to no cone */
    for (int32_t j = (int32_t)floor(ev); j <= (int32_t)ceil(ev) && j < g->h; j++)
        for (int32_t i = (int32_t)floor(eu); i <= (int32_t)ceil(eu) && i < g->w; i++)
            if ((double)i - eu == 0.0 && (double)j - ev == 0.0) {
                uint32_t steps = 0;
                int r = td_viewshed_cast(job->v, job->surface, job->method, job->ex, job->ey, job->ez, i, j,
                                         job->target_height, &steps);
                vis[(size_t)(job->north_first ? g->h - 1 - j : j) * (size_t)g->w + (size_t)i] = r > 0;
            }
    for (started = 0; started < n - 1; started++)
        if (pthread_create(&th[started], NULL, cone_worker, t) != 0)
            break;
    cone_worker(t);
    for (int k = 0; k < started; k++)
        pthread_join(th[k], NULL);
    for (int k = 0; k < 4; k++) {
        sweep *sw = &t->sw[k];
        st->swept += sw->swept;
        st->blocks += sw->blocks;
        st->facing += sw->facing;
        st->rays += sw->rays;
        st->steps += sw->steps;
        oom |= sw->oom; /* its lists: freed by the worker that swept it (cone_worker) */
    }
    if (oom)
        rc = td_err_set(err, TD_ENOMEM, "viewshed: out of memory for the horizon");
    else if (job->cancel && atomic_load_explicit(job->cancel, memory_order_relaxed))
        rc = td_err_set(err, TD_ECANCELED, "viewshed: cancelled");
out:
    free(t);
    return rc;
}

/* Distance between two convex shapes by the GJK algorithm (Gilbert, Johnson and Keerthi, "A
 * fast procedure for computing the distance between complex objects in three-dimensional
 * space", IEEE Journal of Robotics and Automation, 1988), for the compiled collision verdicts
 * of ik/_lm.c. coal stays the reference and the source of penetration witnesses; these verdicts
 * only decide whether shapes come within a distance, without a Python call per pair.
 *
 * A shape is a point, a box, a cylinder (axis z, as coal's) or a convex polytope (its vertices),
 * optionally inflated by a radius: a sphere is a point inflated by its radius. GJK measures the
 * distance between the uninflated cores; the radii are subtracted from it.
 *
 * The closest point of the simplex to the origin is found by Johnson's sub-algorithm written out
 * as a search over the simplex's faces: each face's affine closest point, kept if it lies inside
 * the face (every barycentric coordinate positive), the nearest of those. With at most four
 * points that is 15 small solves, and it needs no case analysis of Voronoi regions.
 */
#ifndef SAHGRASP_GJK_H
#define SAHGRASP_GJK_H

#include <math.h>
#include <string.h>

/* The shape kinds; sahgrasp/ik/_lm.c exports them as module constants SHAPE_*, which
 * sahgrasp/ik/compiled.py reads (never a copy). */
enum { SHAPE_POINT = 0, SHAPE_BOX = 1, SHAPE_CYLINDER = 2, SHAPE_ELLIPSOID = 3, SHAPE_CONVEX = 4 };

typedef struct {
    int kind;
    double R[9];             /* world rotation, row-major */
    double t[3];             /* world position of the shape frame [m] */
    double size[3];          /* box: half extents; cylinder: radius, half length; ellipsoid:
                                radii; convex: half extents of a box holding it [m] */
    double centre[3];        /* convex: centre of that box in the shape frame [m]; else 0 */
    double radius;           /* inflation [m] (a sphere's radius) */
    const double *vertices;  /* convex: local vertices, 3 per vertex [m] */
    int count;               /* convex: number of vertices */
    const int *first;        /* convex, or NULL: per vertex, where its neighbours start in
                                `neighbours` (count + 1 offsets) */
    const int *neighbours;   /* the vertices (this shape's indices) adjacent to each vertex */
    const int *starts;       /* convex with neighbours: per cube-map cell (gjk_cell), the vertex
                                the hill climbing starts from */
} GjkShape;

#define GJK_CELLS 16
#define GJK_DIRECTIONS (6 * GJK_CELLS * GJK_CELLS)

/* The cell of a cube map (6 faces of GJK_CELLS x GJK_CELLS) a direction falls in: where the
 * hill climbing of a convex shape starts, from the vertex farthest along the cell's centre. */
static int gjk_cell(const double *l) {
    int a = 0;
    for (int i = 1; i < 3; i++)
        if (fabs(l[i]) > fabs(l[a])) a = i;
    double m = fabs(l[a]);
    if (m == 0.0) return 0;
    int face = 2 * a + (l[a] < 0.0), cell[2];
    for (int k = 0; k < 2; k++) {
        double u = l[(a + 1 + k) % 3] / m;  /* in [-1, 1] */
        int c = (int)((u + 1.0) * 0.5 * GJK_CELLS);
        cell[k] = c < 0 ? 0 : (c >= GJK_CELLS ? GJK_CELLS - 1 : c);
    }
    return (face * GJK_CELLS + cell[0]) * GJK_CELLS + cell[1];
}

/* The centre direction of cube-map cell `index` (not normalised: only argmax uses it). */
static void gjk_cell_direction(int index, double *l) {
    int face = index / (GJK_CELLS * GJK_CELLS), rest = index % (GJK_CELLS * GJK_CELLS);
    int a = face / 2, cells[2] = {rest / GJK_CELLS, rest % GJK_CELLS};
    l[a] = face % 2 ? -1.0 : 1.0;
    for (int k = 0; k < 2; k++) l[(a + 1 + k) % 3] = -1.0 + (2.0 * cells[k] + 1.0) / GJK_CELLS;
}

static double gjk_dot(const double *a, const double *b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* The point of the shape's core farthest along the world direction d. */
static void gjk_support(const GjkShape *s, const double *d, double *out) {
    double l[3], p[3] = {0.0, 0.0, 0.0};
    for (int i = 0; i < 3; i++) l[i] = s->R[i] * d[0] + s->R[3 + i] * d[1] + s->R[6 + i] * d[2];
    if (s->kind == SHAPE_BOX) {
        for (int i = 0; i < 3; i++) p[i] = l[i] < 0.0 ? -s->size[i] : s->size[i];
    } else if (s->kind == SHAPE_CYLINDER) {
        double rho = sqrt(l[0] * l[0] + l[1] * l[1]);
        if (rho > 0.0) {
            p[0] = s->size[0] * l[0] / rho;
            p[1] = s->size[0] * l[1] / rho;
        }
        p[2] = l[2] < 0.0 ? -s->size[1] : s->size[1];
    } else if (s->kind == SHAPE_ELLIPSOID) {
        double scaled[3], norm = 0.0;
        for (int i = 0; i < 3; i++) {
            scaled[i] = s->size[i] * s->size[i] * l[i];
            norm += scaled[i] * l[i];
        }
        if (norm > 0.0)
            for (int i = 0; i < 3; i++) p[i] = scaled[i] / sqrt(norm);
    } else if (s->kind == SHAPE_CONVEX) {
        int best = s->first == NULL ? 0 : s->starts[gjk_cell(l)];
        double high = gjk_dot(s->vertices + 3 * best, l);
        if (s->first == NULL) {
            for (int k = 1; k < s->count; k++) {
                double h = gjk_dot(s->vertices + 3 * k, l);
                if (h > high) high = h, best = k;
            }
        } else {  /* hill climbing on the hull's edges: a vertex no neighbour beats is a maximum */
            for (int moved = 1; moved;) {
                moved = 0;
                for (int e = s->first[best]; e < s->first[best + 1]; e++) {
                    int k = s->neighbours[e];
                    double h = gjk_dot(s->vertices + 3 * k, l);
                    if (h > high) high = h, best = k, moved = 1;
                }
            }
        }
        memcpy(p, s->vertices + 3 * best, 3 * sizeof(double));
    }
    for (int i = 0; i < 3; i++)
        out[i] = s->R[3 * i] * p[0] + s->R[3 * i + 1] * p[1] + s->R[3 * i + 2] * p[2] + s->t[i];
}

/* The simplex: Minkowski points w = a - b and the support points a, b they came from. */
typedef struct {
    double w[4][3], a[4][3], b[4][3];
    int n;
} GjkSimplex;

/* The affine closest point to the origin of the simplex points `idx[0..k]`: barycentric
 * coordinates into lambda; 0 if the points are affinely dependent. */
static int gjk_affine(const GjkSimplex *s, const int *idx, int k, double *lambda) {
    const double *p0 = s->w[idx[0]];
    double e[3][3], G[3][3], g[3], mu[3] = {0.0, 0.0, 0.0};
    for (int i = 0; i < k; i++)
        for (int c = 0; c < 3; c++) e[i][c] = s->w[idx[i + 1]][c] - p0[c];
    for (int i = 0; i < k; i++) {
        g[i] = -gjk_dot(p0, e[i]);
        for (int j = 0; j < k; j++) G[i][j] = gjk_dot(e[i], e[j]);
    }
    double scale = 1.0;
    for (int i = 0; i < k; i++) scale *= G[i][i];
    if (k == 1) {
        if (G[0][0] <= 0.0) return 0;
        mu[0] = g[0] / G[0][0];
    } else if (k == 2) {
        double det = G[0][0] * G[1][1] - G[0][1] * G[1][0];
        if (det <= 1e-14 * scale) return 0;
        mu[0] = (g[0] * G[1][1] - G[0][1] * g[1]) / det;
        mu[1] = (G[0][0] * g[1] - g[0] * G[1][0]) / det;
    } else if (k == 3) {
        double c00 = G[1][1] * G[2][2] - G[1][2] * G[2][1];
        double c01 = G[1][2] * G[2][0] - G[1][0] * G[2][2];
        double c02 = G[1][0] * G[2][1] - G[1][1] * G[2][0];
        double det = G[0][0] * c00 + G[0][1] * c01 + G[0][2] * c02;
        if (det <= 1e-14 * scale) return 0;
        /* Cramer's rule on the symmetric 3 x 3 system. */
        double c11 = G[0][0] * G[2][2] - G[0][2] * G[2][0];
        double c12 = G[0][1] * G[2][0] - G[0][0] * G[2][1];
        double c22 = G[0][0] * G[1][1] - G[0][1] * G[1][0];
        mu[0] = (c00 * g[0] + c01 * g[1] + c02 * g[2]) / det;
        mu[1] = (c01 * g[0] + c11 * g[1] + c12 * g[2]) / det;
        mu[2] = (c02 * g[0] + c12 * g[1] + c22 * g[2]) / det;
    }
    lambda[0] = 1.0;
    for (int i = 0; i < k; i++) {
        lambda[i + 1] = mu[i];
        lambda[0] -= mu[i];
    }
    return 1;
}

/* The face (points idx[0..k]) nearest the origin among those holding every point of the bit
 * mask `required`, and its barycentric coordinates: k, or -1 if no such face holds its affine
 * closest point inside. */
static int gjk_best_face(const GjkSimplex *s, int required, int *best_idx, double *best_lambda) {
    double best = INFINITY;
    int best_k = -1;
    for (int mask = 1; mask < (1 << s->n); mask++) {
        if ((mask & required) != required) continue;
        int idx[4], k = -1;
        double lambda[4], p[3] = {0.0, 0.0, 0.0};
        for (int i = 0; i < s->n; i++)
            if (mask & (1 << i)) idx[++k] = i;
        if (!gjk_affine(s, idx, k, lambda)) continue;
        int inside = 1;
        for (int i = 0; i <= k && inside; i++) inside = lambda[i] > 0.0;
        if (!inside) continue;
        for (int i = 0; i <= k; i++)
            for (int c = 0; c < 3; c++) p[c] += lambda[i] * s->w[idx[i]][c];
        double d = gjk_dot(p, p);
        if (d < best) {
            best = d, best_k = k;
            memcpy(best_idx, idx, sizeof idx);
            memcpy(best_lambda, lambda, sizeof lambda);
        }
    }
    return best_k;
}

/* Reduce the simplex to the face holding its point nearest the origin; that point into v.
 * That face holds the newest point (GJK's progress guarantees it), and the newest point alone
 * always qualifies, so a face is always found. */
static void gjk_closest(GjkSimplex *s, double *v) {
    int idx[4] = {s->n - 1, 0, 0, 0};
    double lambda[4] = {1.0, 0.0, 0.0, 0.0};
    int k = gjk_best_face(s, 1 << (s->n - 1), idx, lambda);
    GjkSimplex kept;
    kept.n = k + 1;
    for (int i = 0; i < kept.n; i++) {
        memcpy(kept.w[i], s->w[idx[i]], 3 * sizeof(double));
        memcpy(kept.a[i], s->a[idx[i]], 3 * sizeof(double));
        memcpy(kept.b[i], s->b[idx[i]], 3 * sizeof(double));
    }
    memset(v, 0, 3 * sizeof(double));
    for (int i = 0; i < kept.n; i++)
        for (int c = 0; c < 3; c++) v[c] += lambda[i] * kept.w[i][c];
    *s = kept;
}

/* The distance [m] between the cores of a and b (0 if they intersect), or a lower bound of it
 * above `stop_m` as soon as one proves the cores farther apart than that. Relative accuracy
 * about 1e-12 of the distance. */
static double gjk_core_distance(const GjkShape *a, const GjkShape *b, double stop_m) {
    GjkSimplex s;
    double d[3], v[3], minus[3];
    for (int c = 0; c < 3; c++) d[c] = b->t[c] - a->t[c];
    if (gjk_dot(d, d) == 0.0) d[0] = 1.0;
    for (int c = 0; c < 3; c++) minus[c] = -d[c];
    gjk_support(a, d, s.a[0]);
    gjk_support(b, minus, s.b[0]);
    for (int c = 0; c < 3; c++) v[c] = s.w[0][c] = s.a[0][c] - s.b[0][c];
    s.n = 1;
    for (int iteration = 0; iteration < 64; iteration++) {
        double vv = gjk_dot(v, v);
        if (vv <= 1e-30) return 0.0;
        double *a_new = s.a[s.n], *b_new = s.b[s.n], *w = s.w[s.n];
        for (int c = 0; c < 3; c++) minus[c] = -v[c];
        gjk_support(a, minus, a_new);
        gjk_support(b, v, b_new);
        for (int c = 0; c < 3; c++) w[c] = a_new[c] - b_new[c];
        double vw = gjk_dot(v, w);
        if (vw > 0.0 && vw * vw > stop_m * stop_m * vv) return vw / sqrt(vv);
        if (vv - vw <= 1e-12 * vv) break;  /* v is the closest point up to the tolerance */
        double previous[3] = {v[0], v[1], v[2]};
        s.n++;
        gjk_closest(&s, v);
        if (s.n == 4) return 0.0;  /* the origin is inside the tetrahedron */
        if (gjk_dot(v, v) >= vv) {  /* no progress left in floating point */
            memcpy(v, previous, sizeof previous);
            break;
        }
    }
    return sqrt(gjk_dot(v, v));
}

/* A box holding the shape (inflation included) in the shape frame: its centre and half
 * extents; 0 if the shape has none (a convex polytope without its box). */
static int gjk_box_of(const GjkShape *s, double *centre, double *half) {
    double r = s->radius;
    memcpy(centre, s->centre, 3 * sizeof(double));
    if (s->kind == SHAPE_BOX || s->kind == SHAPE_ELLIPSOID || s->kind == SHAPE_CONVEX) {
        for (int i = 0; i < 3; i++) half[i] = s->size[i] + r;
    } else if (s->kind == SHAPE_CYLINDER) {
        half[0] = half[1] = s->size[0] + r;
        half[2] = s->size[1] + r;
    } else {
        half[0] = half[1] = half[2] = r;
    }
    return 1;
}

/* A lower bound [m] of the signed distance between a and b: the largest gap between the boxes
 * holding them along a face normal of either box (the separating-axis test on those six axes;
 * a gap below 0 is an overlap, and the penetration depth is at most the smallest overlap). */
static double gjk_box_gap(const GjkShape *a, const GjkShape *b) {
    double ca[3], cb[3], ha[3], hb[3], d[3], C[9], gap = -INFINITY;
    gjk_box_of(a, ca, ha);
    gjk_box_of(b, cb, hb);
    for (int c = 0; c < 3; c++)  /* between the box centres, world frame */
        d[c] = b->t[c] - a->t[c] +
               (b->R[3 * c] * cb[0] + b->R[3 * c + 1] * cb[1] + b->R[3 * c + 2] * cb[2]) -
               (a->R[3 * c] * ca[0] + a->R[3 * c + 1] * ca[1] + a->R[3 * c + 2] * ca[2]);
    for (int i = 0; i < 3; i++)  /* C = R_a^T R_b */
        for (int j = 0; j < 3; j++)
            C[3 * i + j] = a->R[i] * b->R[j] + a->R[3 + i] * b->R[3 + j] + a->R[6 + i] * b->R[6 + j];
    for (int i = 0; i < 3; i++) {  /* a's axes */
        double along = fabs(a->R[i] * d[0] + a->R[3 + i] * d[1] + a->R[6 + i] * d[2]);
        double reach = ha[i] + hb[0] * fabs(C[3 * i]) + hb[1] * fabs(C[3 * i + 1]) +
                       hb[2] * fabs(C[3 * i + 2]);
        gap = fmax(gap, along - reach);
    }
    for (int j = 0; j < 3; j++) {  /* b's axes */
        double along = fabs(b->R[j] * d[0] + b->R[3 + j] * d[1] + b->R[6 + j] * d[2]);
        double reach = hb[j] + ha[0] * fabs(C[j]) + ha[1] * fabs(C[3 + j]) + ha[2] * fabs(C[6 + j]);
        gap = fmax(gap, along - reach);
    }
    return gap;
}

/* Whether a and b, inflated, come closer than `margin_m` [m] (or intersect; a negative margin
 * asks for a penetration deeper than -margin_m, which needs the inflation: radius_a + radius_b
 * + margin_m > 0). */
static int gjk_within(const GjkShape *a, const GjkShape *b, double margin_m) {
    if (gjk_box_gap(a, b) > margin_m) return 0;
    double reach = a->radius + b->radius + margin_m;
    double d = gjk_core_distance(a, b, reach);
    return d < reach || d <= 0.0;
}

#endif

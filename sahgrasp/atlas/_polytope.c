/* Chart domains of the atlas: convex polytopes cut by half-spaces (see polytope.py).
 *
 * A chart's polytope has a handful of vertices, and an atlas build cuts polytopes hundreds of
 * thousands of times, one plane at a time: per-call interpreter overhead, not arithmetic, was
 * the cost in Python. The arithmetic here is written in the same order as the Python it replaces
 * (no fused multiply-add: setup.py passes -ffp-contract=off), so that for k = 2 the vertices
 * are the same doubles.
 *
 * Vertex/face incidence is kept as bit masks (one bit per face, WORDS 64-bit words). A cut gives
 * its new face the lowest bit no kept vertex uses, so bits are reused as faces disappear.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "../_arrays.h"

#define WORDS 2
#define MAX_FACES (64 * WORDS)

typedef struct {
    uint64_t w[WORDS];
} Mask;

typedef struct {
    PyObject_HEAD
    int k;            /* dimension of the parameter space */
    Py_ssize_t n;     /* vertices */
    Py_ssize_t cap;   /* allocated vertices */
    double *verts;    /* n * k coordinates */
    double *norm2;    /* squared norm of each vertex */
    Mask *masks;      /* faces through each vertex */
    char *blocked;    /* a failed expansion marked the vertex */
    double reach2;    /* largest norm2 */
} Polytope;

static PyTypeObject PolytopeType;

/* -- masks ----------------------------------------------------------------------------------- */

static int mask_popcount(Mask m) {
    int count = 0;
    for (int i = 0; i < WORDS; i++) {
        uint64_t x = m.w[i];
        x = x - ((x >> 1) & 0x5555555555555555ULL);
        x = (x & 0x3333333333333333ULL) + ((x >> 2) & 0x3333333333333333ULL);
        x = (x + (x >> 4)) & 0x0F0F0F0F0F0F0F0FULL;
        count += (int)((x * 0x0101010101010101ULL) >> 56);
    }
    return count;
}

static Mask mask_and(Mask a, Mask b) {
    Mask m;
    for (int i = 0; i < WORDS; i++) m.w[i] = a.w[i] & b.w[i];
    return m;
}

static Mask mask_or(Mask a, Mask b) {
    Mask m;
    for (int i = 0; i < WORDS; i++) m.w[i] = a.w[i] | b.w[i];
    return m;
}

static Mask mask_bit(int bit) {
    Mask m = {{0}};
    m.w[bit / 64] = (uint64_t)1 << (bit % 64);
    return m;
}

/* The lowest bit that ``used`` does not hold; -1 (with an exception set) if all are held. */
static int lowest_free_bit(Mask used, Mask *bit) {
    for (int i = 0; i < WORDS; i++) {
        if (~used.w[i]) {
            Mask m = {{0}};
            m.w[i] = ~used.w[i] & (used.w[i] + 1);
            *bit = m;
            return 0;
        }
    }
    PyErr_Format(PyExc_ValueError, "a polytope may have at most %d faces", MAX_FACES);
    return -1;
}

/* -- storage --------------------------------------------------------------------------------- */

static Polytope *poly_new(int k, Py_ssize_t cap) {
    Polytope *p = PyObject_New(Polytope, &PolytopeType);
    if (p == NULL) return NULL;
    if (cap < 1) cap = 1;
    p->k = k;
    p->n = 0;
    p->cap = cap;
    p->verts = PyMem_Malloc(sizeof(double) * (size_t)(cap * k));
    p->norm2 = PyMem_Malloc(sizeof(double) * (size_t)cap);
    p->masks = PyMem_Malloc(sizeof(Mask) * (size_t)cap);
    p->blocked = PyMem_Malloc((size_t)cap);
    p->reach2 = 0.0;
    if (!p->verts || !p->norm2 || !p->masks || !p->blocked) {
        Py_DECREF(p);
        PyErr_NoMemory();
        return NULL;
    }
    return p;
}

static void poly_dealloc(Polytope *p) {
    PyMem_Free(p->verts);
    PyMem_Free(p->norm2);
    PyMem_Free(p->masks);
    PyMem_Free(p->blocked);
    PyObject_Free(p);
}

static int poly_reserve(Polytope *p, Py_ssize_t cap) {
    if (cap <= p->cap) return 0;
    if (cap < 2 * p->cap) cap = 2 * p->cap;
    double *verts = PyMem_Realloc(p->verts, sizeof(double) * (size_t)(cap * p->k));
    if (verts) p->verts = verts;
    double *norm2 = PyMem_Realloc(p->norm2, sizeof(double) * (size_t)cap);
    if (norm2) p->norm2 = norm2;
    Mask *masks = PyMem_Realloc(p->masks, sizeof(Mask) * (size_t)cap);
    if (masks) p->masks = masks;
    char *blocked = PyMem_Realloc(p->blocked, (size_t)cap);
    if (blocked) p->blocked = blocked;
    if (!verts || !norm2 || !masks || !blocked) {
        PyErr_NoMemory();
        return -1;
    }
    p->cap = cap;
    return 0;
}

/* Append a vertex (norm2 computed left to right, as Python's sum of products). */
static int poly_push(Polytope *p, const double *v, Mask mask, char blocked) {
    if (poly_reserve(p, p->n + 1) < 0) return -1;
    double *dst = p->verts + p->n * p->k, norm2 = 0.0;
    for (int d = 0; d < p->k; d++) {
        dst[d] = v[d];
        norm2 += v[d] * v[d];
    }
    p->norm2[p->n] = norm2;
    p->masks[p->n] = mask;
    p->blocked[p->n] = blocked;
    p->n++;
    return 0;
}

/* Copy vertex i of src, with its norm2, onto the end of dst. */
static int poly_push_from(Polytope *dst, const Polytope *src, Py_ssize_t i, Mask mask) {
    if (poly_reserve(dst, dst->n + 1) < 0) return -1;
    memcpy(dst->verts + dst->n * dst->k, src->verts + i * src->k, sizeof(double) * src->k);
    dst->norm2[dst->n] = src->norm2[i];
    dst->masks[dst->n] = mask;
    dst->blocked[dst->n] = src->blocked[i];
    dst->n++;
    return 0;
}

static int poly_finish(Polytope *p) {
    if (p->n == 0) {
        PyErr_SetString(PyExc_ValueError, "a cut removed every vertex of the polytope");
        return -1;
    }
    double reach2 = p->norm2[0];
    for (Py_ssize_t i = 1; i < p->n; i++)
        if (p->norm2[i] > reach2) reach2 = p->norm2[i];
    p->reach2 = reach2;
    return 0;
}

/* Move the vertices of src into p (src is emptied and freed). */
static void poly_take(Polytope *p, Polytope *src) {
    double *verts = p->verts, *norm2 = p->norm2;
    Mask *masks = p->masks;
    char *blocked = p->blocked;
    p->verts = src->verts;
    p->norm2 = src->norm2;
    p->masks = src->masks;
    p->blocked = src->blocked;
    p->n = src->n;
    p->cap = src->cap;
    p->reach2 = src->reach2;
    src->verts = verts;
    src->norm2 = norm2;
    src->masks = masks;
    src->blocked = blocked;
    Py_DECREF(src);
}

/* Replace the vertices of p by those of out (consumed): 1, or -1 with an exception. */
static int poly_replace(Polytope *p, Polytope *out) {
    if (poly_finish(out) < 0) {
        Py_DECREF(out);
        return -1;
    }
    poly_take(p, out);
    return 1;
}

/* -- arguments ------------------------------------------------------------------------------- */

/* Read ``k`` floats of a sequence into out; -1 with an exception if it is not that. */
static int read_vector(PyObject *seq, int k, double *out, const char *what) {
    PyObject *fast = PySequence_Fast(seq, what);
    if (fast == NULL) {
        if (PyErr_ExceptionMatches(PyExc_TypeError)) {
            PyErr_Clear();
            PyErr_Format(PyExc_TypeError, "%s must be a sequence of %d floats, got %.100s", what,
                         k, Py_TYPE(seq)->tp_name);
        }
        return -1;
    }
    if (PySequence_Fast_GET_SIZE(fast) != k) {
        PyErr_Format(PyExc_ValueError, "%s must have %d entries, got %zd", what, k,
                     PySequence_Fast_GET_SIZE(fast));
        Py_DECREF(fast);
        return -1;
    }
    PyObject **items = PySequence_Fast_ITEMS(fast);
    for (int d = 0; d < k; d++) {
        out[d] = PyFloat_AsDouble(items[d]);
        if (out[d] == -1.0 && PyErr_Occurred()) {
            if (PyErr_ExceptionMatches(PyExc_TypeError)) {
                PyErr_Clear();
                PyErr_Format(PyExc_TypeError, "%s[%d] must be a real number, got %.100s", what, d,
                             Py_TYPE(items[d])->tp_name);
            }
            Py_DECREF(fast);
            return -1;
        }
    }
    Py_DECREF(fast);
    return 0;
}

/* -- cuts ------------------------------------------------------------------------------------ */

/* Signed distances a . v - b of every vertex into d; returns the largest. */
static double distances(const Polytope *p, const double *a, double b, double *d) {
    double largest = -INFINITY;
    for (Py_ssize_t i = 0; i < p->n; i++) {
        const double *v = p->verts + i * p->k;
        double s = 0.0;
        for (int c = 0; c < p->k; c++) s += a[c] * v[c];
        d[i] = s - b;
        if (d[i] > largest) largest = d[i];
    }
    return largest;
}

static int face_bit(const Polytope *p, const double *d, double tol, Mask *bit) {
    Mask used = {{0}};
    for (Py_ssize_t i = 0; i < p->n; i++)
        if (d[i] <= tol) used = mask_or(used, p->masks[i]);
    return lowest_free_bit(used, bit);
}

/* General cut: every edge (two vertices sharing k - 1 faces) from a vertex strictly inside to a
 * removed one gives a new vertex on the plane. Returns 1 if something was removed, 0 if not, -1
 * on error. */
static int cut_general(Polytope *p, const double *a, double b, double tol, double *d) {
    if (distances(p, a, b, d) <= tol) return 0;
    Mask bit;
    if (face_bit(p, d, tol, &bit) < 0) return -1;
    Polytope *out = poly_new(p->k, p->n + 4);
    if (out == NULL) return -1;
    for (Py_ssize_t i = 0; i < p->n; i++) {
        if (d[i] > tol) continue;
        Mask m = d[i] >= -tol ? mask_or(p->masks[i], bit) : p->masks[i];
        if (poly_push_from(out, p, i, m) < 0) goto fail;
    }
    int k1 = p->k - 1;
    double v[MAX_FACES / 2];
    for (Py_ssize_t i = 0; i < p->n; i++) {
        if (d[i] > tol || d[i] >= -tol) continue;
        const double *vi = p->verts + i * p->k;
        for (Py_ssize_t o = 0; o < p->n; o++) {
            if (d[o] <= tol) continue;
            Mask shared = mask_and(p->masks[i], p->masks[o]);
            if (mask_popcount(shared) < k1) continue;
            double t = d[i] / (d[i] - d[o]);
            const double *vo = p->verts + o * p->k;
            for (int c = 0; c < p->k; c++) v[c] = vi[c] + t * (vo[c] - vi[c]);
            if (poly_push(out, v, mask_or(shared, bit), 0) < 0) goto fail;
        }
    }
    return poly_replace(p, out);
fail:
    Py_DECREF(out);
    return -1;
}

/* Cut of a polygon whose vertices go round counter-clockwise: one pass round its edges keeps
 * the order. An edge from a vertex strictly inside to one strictly outside (or back) gives a new
 * vertex, computed from the inner end as cut_general does. */
static int clip(Polytope *p, const double *a, double b, double tol, double *d) {
    if (distances(p, a, b, d) <= tol) return 0;
    Mask bit;
    if (face_bit(p, d, tol, &bit) < 0) return -1;
    Polytope *out = poly_new(2, p->n + 2);
    if (out == NULL) return -1;
    for (Py_ssize_t i = 0; i < p->n; i++) {
        Py_ssize_t j = i + 1 < p->n ? i + 1 : 0;
        double di = d[i], dj = d[j];
        if (di <= tol) {
            Mask m = di >= -tol ? mask_or(p->masks[i], bit) : p->masks[i];
            if (poly_push_from(out, p, i, m) < 0) goto fail;
        }
        if ((di < -tol && dj > tol) || (di > tol && dj < -tol)) {
            Py_ssize_t inner = di < 0 ? i : j, outer = di < 0 ? j : i;
            double t = di < 0 ? di / (di - dj) : dj / (dj - di);
            const double *q0 = p->verts + 2 * inner, *q1 = p->verts + 2 * outer;
            double v[2] = {q0[0] + t * (q1[0] - q0[0]), q0[1] + t * (q1[1] - q0[1])};
            Mask m = mask_or(mask_and(p->masks[i], p->masks[j]), bit);
            if (poly_push(out, v, m, 0) < 0) goto fail;
        }
    }
    return poly_replace(p, out);
fail:
    Py_DECREF(out);
    return -1;
}

static int poly_cut(Polytope *p, const double *a, double b, double tol) {
    double small[64];
    double *d = p->n <= 64 ? small : PyMem_Malloc(sizeof(double) * p->n);
    if (d == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    int removed = p->k == 2 ? clip(p, a, b, tol, d) : cut_general(p, a, b, tol, d);
    if (d != small) PyMem_Free(d);
    return removed;
}

/* -- construction ---------------------------------------------------------------------------- */

static int check_k(int k) {
    if (k >= 1 && 2 * k <= MAX_FACES) return 0;
    PyErr_Format(PyExc_ValueError, "k must be in [1, %d], got %d", MAX_FACES / 2, k);
    return -1;
}

static Polytope *cube(int k, double r) {
    if (check_k(k) < 0) return NULL;
    Py_ssize_t count = (Py_ssize_t)1 << k;
    Polytope *p = poly_new(k, count);
    if (p == NULL) return NULL;
    /* itertools.product((-r, r), repeat=k) order; k = 2 goes counter-clockwise instead. */
    static const Py_ssize_t square[4] = {0, 2, 3, 1};
    double v[MAX_FACES / 2];
    for (Py_ssize_t n = 0; n < count; n++) {
        Py_ssize_t code = k == 2 ? square[n] : n;
        Mask mask = {{0}};
        for (int d = 0; d < k; d++) {
            int negative = !((code >> (k - 1 - d)) & 1);
            v[d] = negative ? -r : r;
            mask = mask_or(mask, mask_bit(2 * d + negative));
        }
        if (poly_push(p, v, mask, 0) < 0) {
            Py_DECREF(p);
            return NULL;
        }
    }
    poly_finish(p);
    return p;
}

typedef struct {
    double x, y;
    Py_ssize_t index;
} DualPoint;

static int dual_order(const void *pa, const void *pb) {
    const DualPoint *a = pa, *b = pb;
    if (a->x != b->x) return a->x < b->x ? -1 : 1;
    if (a->y != b->y) return a->y < b->y ? -1 : 1;
    return a->index < b->index ? -1 : (a->index > b->index);
}

/* One half of Andrew's monotone chain over pts[from], pts[from + step], ...: hull points turning
 * strictly left, written into out; returns their count. */
static Py_ssize_t chain(const DualPoint *pts, Py_ssize_t n, int reverse, Py_ssize_t *out) {
    Py_ssize_t m = 0;
    for (Py_ssize_t s = 0; s < n; s++) {
        Py_ssize_t i = reverse ? n - 1 - s : s;
        double x = pts[i].x, y = pts[i].y;
        while (m >= 2) {
            const DualPoint *A = &pts[out[m - 2]], *B = &pts[out[m - 1]];
            if ((B->x - A->x) * (y - A->y) - (B->y - A->y) * (x - A->x) > 0) break;
            m--;
        }
        out[m++] = i;
    }
    return m;
}

/* Polygon {w : p . w <= 1 for p in dual}: consecutive points of the dual hull give its vertices,
 * counter-clockwise round the origin. */
static Polytope *from_dual_polygon(DualPoint *pts, Py_ssize_t n) {
    qsort(pts, (size_t)n, sizeof(DualPoint), dual_order);
    Py_ssize_t *lower = PyMem_Malloc(sizeof(Py_ssize_t) * (size_t)(2 * n + 2));
    if (lower == NULL) return (Polytope *)PyErr_NoMemory();
    Py_ssize_t *upper = lower + n + 1;
    Py_ssize_t nl = chain(pts, n, 0, lower), nu = chain(pts, n, 1, upper);
    Py_ssize_t m = (nl - 1) + (nu - 1);
    if (m > MAX_FACES || m < 3) {
        PyMem_Free(lower);
        PyErr_Format(PyExc_ValueError, "a polygon must have 3 to %d edges, got %zd", MAX_FACES, m);
        return NULL;
    }
    Py_ssize_t hull[MAX_FACES];
    for (Py_ssize_t e = 0; e < nl - 1; e++) hull[e] = lower[e];
    for (Py_ssize_t e = 0; e < nu - 1; e++) hull[nl - 1 + e] = upper[e];
    PyMem_Free(lower);
    Polytope *p = poly_new(2, m);
    if (p == NULL) return NULL;
    for (Py_ssize_t e = 0; e < m; e++) {
        const DualPoint *s = &pts[hull[e]], *t = &pts[hull[e + 1 < m ? e + 1 : 0]];
        double det = s->x * t->y - s->y * t->x; /* the vertex solves s . v = t . v = 1 */
        if (det == 0.0) {
            Py_DECREF(p);
            PyErr_SetString(PyExc_ValueError, "degenerate polygon: two planes are parallel");
            return NULL;
        }
        double v[2] = {(t->y - s->y) / det, (s->x - t->x) / det};
        /* face bits by position round the hull: vertex e lies on faces e and e + 1 */
        poly_push(p, v, mask_or(mask_bit((int)e), mask_bit((int)((e + 1) % m))), 0);
    }
    poly_finish(p);
    return p;
}

static int read_planes(PyObject *planes, PyObject *offsets, int k, double **a, double **b,
                       Py_ssize_t *count) {
    PyObject *fp = PySequence_Fast(planes, "planes must be a sequence");
    if (fp == NULL) return -1;
    PyObject *fo = PySequence_Fast(offsets, "offsets must be a sequence");
    if (fo == NULL) {
        Py_DECREF(fp);
        return -1;
    }
    Py_ssize_t n = PySequence_Fast_GET_SIZE(fp);
    int status = -1;
    *a = NULL;
    *b = NULL;
    if (PySequence_Fast_GET_SIZE(fo) != n) {
        PyErr_SetString(PyExc_ValueError, "planes and offsets must have the same length");
        goto done;
    }
    *a = PyMem_Malloc(sizeof(double) * (size_t)(n * k + 1));
    *b = PyMem_Malloc(sizeof(double) * (size_t)(n + 1));
    if (*a == NULL || *b == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    for (Py_ssize_t h = 0; h < n; h++) {
        char plane[48];
        PyOS_snprintf(plane, sizeof plane, "planes[%zd]", h);
        if (read_vector(PySequence_Fast_GET_ITEM(fp, h), k, *a + h * k, plane) < 0) goto done;
        PyObject *offset = PySequence_Fast_GET_ITEM(fo, h);
        (*b)[h] = PyFloat_AsDouble(offset);
        if ((*b)[h] == -1.0 && PyErr_Occurred()) {
            if (PyErr_ExceptionMatches(PyExc_TypeError)) {
                PyErr_Clear();
                PyErr_Format(PyExc_TypeError, "offsets[%zd] must be a real number, got %.100s", h,
                             Py_TYPE(offset)->tp_name);
            }
            goto done;
        }
    }
    *count = n;
    status = 0;
done:
    if (status < 0) {
        PyMem_Free(*a);
        PyMem_Free(*b);
        *a = *b = NULL;
    }
    Py_DECREF(fp);
    Py_DECREF(fo);
    return status;
}

/* -- Python methods -------------------------------------------------------------------------- */

static PyObject *Polytope_cube(PyObject *cls, PyObject *args) {
    int k;
    double r;
    PyObject *k_obj;
    if (!PyArg_ParseTuple(args, "Od:cube", &k_obj, &r) ||
        get_int(k_obj, &k, 1, MAX_FACES / 2, "k") < 0)
        return NULL;
    return (PyObject *)cube(k, r);
}

static PyObject *Polytope_from_planes(PyObject *cls, PyObject *args) {
    int k;
    double r, tol;
    PyObject *k_obj, *planes, *offsets;
    if (!PyArg_ParseTuple(args, "OdOOd:from_planes", &k_obj, &r, &planes, &offsets, &tol) ||
        get_int(k_obj, &k, 1, MAX_FACES / 2, "k") < 0)
        return NULL;
    double *a, *b;
    Py_ssize_t n;
    if (read_planes(planes, offsets, k, &a, &b, &n) < 0) return NULL;
    Polytope *p = NULL;
    if (k == 2) {
        DualPoint *pts = PyMem_Malloc(sizeof(DualPoint) * (size_t)(n + 4));
        if (pts == NULL) {
            PyErr_NoMemory();
        } else {
            double inv = 1.0 / r;
            const double cube_dual[4][2] = {{inv, 0.0}, {-inv, 0.0}, {0.0, inv}, {0.0, -inv}};
            for (Py_ssize_t h = 0; h < 4; h++)
                pts[h] = (DualPoint){cube_dual[h][0], cube_dual[h][1], h};
            for (Py_ssize_t h = 0; h < n; h++)
                pts[4 + h] = (DualPoint){a[2 * h] / b[h], a[2 * h + 1] / b[h], 4 + h};
            p = from_dual_polygon(pts, n + 4);
            PyMem_Free(pts);
        }
    } else {
        p = cube(k, r);
        for (Py_ssize_t h = 0; p != NULL && h < n; h++) {
            if (poly_cut(p, a + h * k, b[h], tol) < 0) Py_CLEAR(p);
        }
    }
    PyMem_Free(a);
    PyMem_Free(b);
    return (PyObject *)p;
}

static PyObject *Polytope_copy(Polytope *self, PyObject *unused) {
    Polytope *p = poly_new(self->k, self->n);
    if (p == NULL) return NULL;
    memcpy(p->verts, self->verts, sizeof(double) * (size_t)(self->n * self->k));
    memcpy(p->norm2, self->norm2, sizeof(double) * (size_t)self->n);
    memcpy(p->masks, self->masks, sizeof(Mask) * (size_t)self->n);
    memcpy(p->blocked, self->blocked, (size_t)self->n);
    p->n = self->n;
    p->reach2 = self->reach2;
    return (PyObject *)p;
}

/* -- serialisation (atlas checkpoints) ------------------------------------------------------
 * The bytes are: int32 k, int32 0 (padding), int64 n, double reach2, then n*k vertex coordinates,
 * n squared norms, n masks (WORDS uint64 each) and n blocked flags, all in native byte order:
 * a checkpoint is read back on the machine that wrote it. */

#define STATE_HEADER (2 * sizeof(int32_t) + sizeof(int64_t) + sizeof(double))

static size_t state_size(int k, Py_ssize_t n) {
    return STATE_HEADER + (size_t)n * (sizeof(double) * (size_t)(k + 1) + sizeof(Mask) + 1);
}

static PyObject *Polytope_to_bytes(Polytope *self, PyObject *unused) {
    size_t size = state_size(self->k, self->n);
    PyObject *out = PyBytes_FromStringAndSize(NULL, (Py_ssize_t)size);
    if (out == NULL) return NULL;
    char *b = PyBytes_AS_STRING(out);
    int32_t head[2] = {self->k, 0};
    int64_t n = self->n;
    memcpy(b, head, sizeof(head));
    b += sizeof(head);
    memcpy(b, &n, sizeof(n));
    b += sizeof(n);
    memcpy(b, &self->reach2, sizeof(double));
    b += sizeof(double);
    memcpy(b, self->verts, sizeof(double) * (size_t)(self->n * self->k));
    b += sizeof(double) * (size_t)(self->n * self->k);
    memcpy(b, self->norm2, sizeof(double) * (size_t)self->n);
    b += sizeof(double) * (size_t)self->n;
    memcpy(b, self->masks, sizeof(Mask) * (size_t)self->n);
    b += sizeof(Mask) * (size_t)self->n;
    memcpy(b, self->blocked, (size_t)self->n);
    return out;
}

static PyObject *Polytope_from_bytes(PyObject *cls, PyObject *arg) {
    Py_buffer view;
    if (PyObject_GetBuffer(arg, &view, PyBUF_SIMPLE) < 0) return NULL;
    const char *b = view.buf;
    int32_t head[2];
    int64_t n;
    PyObject *result = NULL;
    if ((size_t)view.len < STATE_HEADER) goto bad;
    memcpy(head, b, sizeof(head));
    memcpy(&n, b + sizeof(head), sizeof(n));
    if (head[0] < 1 || head[0] > MAX_FACES / 2 || head[1] != 0 || n < 0 ||
        n > (int64_t)(PY_SSIZE_T_MAX / 1024) || (size_t)view.len != state_size(head[0], (Py_ssize_t)n))
        goto bad;
    Polytope *p = poly_new(head[0], (Py_ssize_t)n);
    if (p == NULL) goto done;
    const char *c = b + sizeof(head) + sizeof(n);
    memcpy(&p->reach2, c, sizeof(double));
    c += sizeof(double);
    memcpy(p->verts, c, sizeof(double) * (size_t)(n * head[0]));
    c += sizeof(double) * (size_t)(n * head[0]);
    memcpy(p->norm2, c, sizeof(double) * (size_t)n);
    c += sizeof(double) * (size_t)n;
    memcpy(p->masks, c, sizeof(Mask) * (size_t)n);
    c += sizeof(Mask) * (size_t)n;
    memcpy(p->blocked, c, (size_t)n);
    p->n = (Py_ssize_t)n;
    result = (PyObject *)p;
    goto done;
bad:
    PyErr_SetString(PyExc_ValueError, "not the bytes of a polytope (Polytope.to_bytes)");
done:
    PyBuffer_Release(&view);
    return result;
}

static PyObject *Polytope_expandable(Polytope *self, PyObject *arg) {
    double r2 = PyFloat_AsDouble(arg);
    if (r2 == -1.0 && PyErr_Occurred()) return NULL;
    double best = INFINITY;
    Py_ssize_t v = -1;
    for (Py_ssize_t i = 0; i < self->n; i++) {
        double n2 = self->norm2[i];
        if (r2 <= n2 && n2 < best && !self->blocked[i]) {
            best = n2;
            v = i;
        }
    }
    return PyLong_FromSsize_t(v);
}

static PyObject *Polytope_cut(Polytope *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "cut(a, b, tol) takes 3 arguments");
        return NULL;
    }
    double a[MAX_FACES / 2];
    if (read_vector(args[0], self->k, a, "a") < 0) return NULL;
    double b = PyFloat_AsDouble(args[1]), tol = PyFloat_AsDouble(args[2]);
    if (PyErr_Occurred()) return NULL;
    int removed = poly_cut(self, a, b, tol);
    if (removed < 0) return NULL;
    return PyBool_FromLong(removed);
}

static int vertex_index(Polytope *self, PyObject *arg, Py_ssize_t *i) {
    *i = PyLong_AsSsize_t(arg);
    if (*i == -1 && PyErr_Occurred()) return -1;
    if (*i < 0 || *i >= self->n) {
        PyErr_Format(PyExc_IndexError, "vertex %zd of a polytope with %zd", *i, self->n);
        return -1;
    }
    return 0;
}

static PyObject *vertex_tuple(const Polytope *self, Py_ssize_t i) {
    PyObject *t = PyTuple_New(self->k);
    if (t == NULL) return NULL;
    for (int d = 0; d < self->k; d++) {
        PyObject *x = PyFloat_FromDouble(self->verts[i * self->k + d]);
        if (x == NULL) {
            Py_DECREF(t);
            return NULL;
        }
        PyTuple_SET_ITEM(t, d, x);
    }
    return t;
}

static PyObject *Polytope_vertex(Polytope *self, PyObject *arg) {
    Py_ssize_t i;
    if (vertex_index(self, arg, &i) < 0) return NULL;
    return vertex_tuple(self, i);
}

static PyObject *Polytope_vertex_norm2(Polytope *self, PyObject *arg) {
    Py_ssize_t i;
    if (vertex_index(self, arg, &i) < 0) return NULL;
    return PyFloat_FromDouble(self->norm2[i]);
}

static PyObject *Polytope_block(Polytope *self, PyObject *arg) {
    Py_ssize_t i;
    if (vertex_index(self, arg, &i) < 0) return NULL;
    self->blocked[i] = 1;
    Py_RETURN_NONE;
}

static PyObject *Polytope_index(Polytope *self, PyObject *arg) {
    double v[MAX_FACES / 2];
    if (read_vector(arg, self->k, v, "vertex") < 0) return NULL;
    for (Py_ssize_t i = 0; i < self->n; i++) {
        const double *w = self->verts + i * self->k;
        int d = 0;
        while (d < self->k && w[d] == v[d]) d++;
        if (d == self->k) return PyLong_FromSsize_t(i);
    }
    PyErr_SetString(PyExc_ValueError, "the vertex is not one of the polytope's");
    return NULL;
}

/* One Python object per vertex, as a list: the getters below differ only in the item. */
typedef PyObject *(*VertexItem)(const Polytope *, Py_ssize_t);

static PyObject *vertex_list(const Polytope *self, VertexItem item) {
    PyObject *list = PyList_New(self->n);
    if (list == NULL) return NULL;
    for (Py_ssize_t i = 0; i < self->n; i++) {
        PyObject *x = item(self, i);
        if (x == NULL) {
            Py_DECREF(list);
            return NULL;
        }
        PyList_SET_ITEM(list, i, x);
    }
    return list;
}

static PyObject *mask_int(const Polytope *self, Py_ssize_t i) {
    PyObject *shift = PyLong_FromLong(64);
    if (shift == NULL) return NULL;
    PyObject *value = PyLong_FromLong(0);
    for (int w = WORDS - 1; value != NULL && w >= 0; w--) {
        PyObject *word = PyLong_FromUnsignedLongLong(self->masks[i].w[w]);
        PyObject *high = word ? PyNumber_Lshift(value, shift) : NULL;
        Py_DECREF(value);
        value = high ? PyNumber_Or(high, word) : NULL;
        Py_XDECREF(high);
        Py_XDECREF(word);
    }
    Py_DECREF(shift);
    return value;
}

static PyObject *norm2_float(const Polytope *self, Py_ssize_t i) {
    return PyFloat_FromDouble(self->norm2[i]);
}

static PyObject *blocked_bool(const Polytope *self, Py_ssize_t i) {
    return PyBool_FromLong(self->blocked[i]);
}

static PyObject *Polytope_get_verts(Polytope *self, void *closure) {
    return vertex_list(self, vertex_tuple);
}

static PyObject *Polytope_get_masks(Polytope *self, void *closure) {
    return vertex_list(self, mask_int);
}

static PyObject *Polytope_get_norm2(Polytope *self, void *closure) {
    return vertex_list(self, norm2_float);
}

static PyObject *Polytope_get_blocked(Polytope *self, void *closure) {
    return vertex_list(self, blocked_bool);
}

static PyObject *Polytope_get_reach2(Polytope *self, void *closure) {
    return PyFloat_FromDouble(self->reach2);
}

static PyObject *Polytope_get_k(Polytope *self, void *closure) { return PyLong_FromLong(self->k); }

static Py_ssize_t Polytope_len(Polytope *self) { return self->n; }

static PyMethodDef Polytope_methods[] = {
    {"cube", (PyCFunction)Polytope_cube, METH_VARARGS | METH_CLASS,
     "cube(k, r): the k-cube [-r, r]^k; face 2d+s is x_d = -+r (k = 2: counter-clockwise)."},
    {"from_planes", (PyCFunction)Polytope_from_planes, METH_VARARGS | METH_CLASS,
     "from_planes(k, r, planes, offsets, tol): the cube [-r, r]^k cut by every half-space\n"
     "planes[h] . w <= offsets[h] (> 0); k = 2 through the dual polygon, otherwise one cut per\n"
     "plane in order."},
    {"copy", (PyCFunction)Polytope_copy, METH_NOARGS, "An independent copy."},
    {"to_bytes", (PyCFunction)Polytope_to_bytes, METH_NOARGS,
     "to_bytes(): the whole state (vertices, norms, masks, blocked flags) as bytes."},
    {"from_bytes", (PyCFunction)Polytope_from_bytes, METH_O | METH_CLASS,
     "from_bytes(data): the polytope whose to_bytes() gave data; ValueError if data is not."},
    {"expandable", (PyCFunction)Polytope_expandable, METH_O,
     "expandable(r2): index of the nearest unblocked vertex with squared norm >= r2, or -1."},
    {"cut", (PyCFunction)(void (*)(void))Polytope_cut, METH_FASTCALL,
     "cut(a, b, tol): intersect with a . w <= b; True when a vertex was removed."},
    {"vertex", (PyCFunction)Polytope_vertex, METH_O, "vertex(i): vertex i as a tuple."},
    {"vertex_norm2", (PyCFunction)Polytope_vertex_norm2, METH_O,
     "vertex_norm2(i): squared norm of vertex i."},
    {"block", (PyCFunction)Polytope_block, METH_O, "block(i): mark vertex i as blocked."},
    {"index", (PyCFunction)Polytope_index, METH_O,
     "index(vertex): index of the vertex equal to the given one; ValueError if none."},
    {NULL, NULL, 0, NULL},
};

static PyGetSetDef Polytope_getset[] = {
    {"verts", (getter)Polytope_get_verts, NULL, "Vertices, a list of tuples.", NULL},
    {"masks", (getter)Polytope_get_masks, NULL, "Faces through each vertex, as int bit masks.", NULL},
    {"norm2", (getter)Polytope_get_norm2, NULL, "Squared norm of each vertex.", NULL},
    {"blocked", (getter)Polytope_get_blocked, NULL, "Blocked flag of each vertex.", NULL},
    {"reach2", (getter)Polytope_get_reach2, NULL, "Largest squared vertex norm.", NULL},
    {"k", (getter)Polytope_get_k, NULL, "Dimension.", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PySequenceMethods Polytope_as_sequence = {
    .sq_length = (lenfunc)Polytope_len,
};

static PyTypeObject PolytopeType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "sahgrasp.atlas._polytope.Polytope",
    .tp_doc = "Convex polytope in a chart's parameter space (vertices and face masks).",
    .tp_basicsize = sizeof(Polytope),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_dealloc = (destructor)poly_dealloc,
    .tp_methods = Polytope_methods,
    .tp_getset = Polytope_getset,
    .tp_as_sequence = &Polytope_as_sequence,
};

/* -- the compatibility test of a wave's tries (builder._Builder._compatible) ---------------- */

/* Smallest eigenvalue of the symmetric k x k matrix g (destroyed), by cyclic Jacobi sweeps. */
static double min_eigenvalue(double *g, Py_ssize_t k) {
    for (int sweep = 0; sweep < 64; sweep++) {
        double off = 0.0;
        for (Py_ssize_t i = 0; i < k; i++)
            for (Py_ssize_t j = i + 1; j < k; j++) off += g[i * k + j] * g[i * k + j];
        if (off == 0.0) break;
        for (Py_ssize_t p = 0; p < k; p++) {
            for (Py_ssize_t q = p + 1; q < k; q++) {
                double gpq = g[p * k + q];
                if (gpq == 0.0) continue;
                double theta = (g[q * k + q] - g[p * k + p]) / (2.0 * gpq);
                double t = (theta >= 0.0 ? 1.0 : -1.0) / (fabs(theta) + sqrt(theta * theta + 1.0));
                double c = 1.0 / sqrt(t * t + 1.0), s = t * c;
                for (Py_ssize_t m = 0; m < k; m++) { /* columns p and q */
                    double gp = g[m * k + p], gq = g[m * k + q];
                    g[m * k + p] = c * gp - s * gq;
                    g[m * k + q] = s * gp + c * gq;
                }
                for (Py_ssize_t m = 0; m < k; m++) { /* rows p and q */
                    double gp = g[p * k + m], gq = g[q * k + m];
                    g[p * k + m] = c * gp - s * gq;
                    g[q * k + m] = s * gp + c * gq;
                }
            }
        }
    }
    double smallest = g[0];
    for (Py_ssize_t i = 1; i < k; i++)
        if (g[i * k + i] < smallest) smallest = g[i * k + i];
    return smallest;
}

/* Whether the bases phi (n x k) and base (n x k) are alike: the smallest singular value of
 * phi^T base squared is at least ``threshold`` (builder._Builder._similar). */
static int alike(const double *phi, const double *base, Py_ssize_t n, int k, double threshold,
                 double *m, double *g) {
    double fro = 0.0;
    for (int a = 0; a < k; a++) {
        for (int b = 0; b < k; b++) {
            double s = 0.0;
            for (Py_ssize_t j = 0; j < n; j++) s += phi[j * k + a] * base[j * k + b];
            m[a * k + b] = s;
            fro += s * s;
        }
    }
    if (!(fro - (k - 1) < threshold)) return 1; /* |M|_F^2 - (k - 1) bounds sigma_min^2 below */
    for (int a = 0; a < k; a++) {
        for (int b = 0; b < k; b++) {
            double s = 0.0;
            for (int c = 0; c < k; c++) s += m[c * k + a] * m[c * k + b];
            g[a * k + b] = s;
        }
    }
    return !(min_eigenvalue(g, k) < threshold);
}

/* Chart ``poly`` cut by the planes ``a[h] . w <= b[h]`` (h in use) still expands ``vertex``. */
static int still_picked(const Polytope *poly, const double *vertex, const double *a,
                        const double *b, const Py_ssize_t *use, Py_ssize_t count, double tol,
                        double r2) {
    Polytope *p = (Polytope *)Polytope_copy((Polytope *)poly, NULL);
    if (p == NULL) return -1;
    int k = p->k;
    for (Py_ssize_t h = 0; h < count; h++) {
        Py_ssize_t at = use[h];
        if (0.5 * b[at] < p->reach2 && poly_cut(p, a + at * k, b[at], tol) < 0) {
            Py_DECREF(p);
            return -1;
        }
    }
    double best = INFINITY;
    Py_ssize_t v = -1;
    for (Py_ssize_t i = 0; i < p->n; i++) { /* Polytope.expandable */
        double n2 = p->norm2[i];
        if (r2 <= n2 && n2 < best && !p->blocked[i]) {
            best = n2;
            v = i;
        }
    }
    int same = v >= 0;
    for (int d = 0; same && d < k; d++) same = p->verts[v * k + d] == vertex[d];
    Py_DECREF(p);
    return same;
}

static PyObject *compatible(PyObject *mod, PyObject *args) {
    PyObject *polys, *objs[5];
    double r, r2, tol, threshold;
    if (!PyArg_ParseTuple(args, "OOOOOOdddd", &polys, &objs[0], &objs[1], &objs[2], &objs[3],
                          &objs[4], &r, &r2, &tol, &threshold))
        return NULL;
    static const char *names[5] = {"centres", "parent_centres", "phi", "parent_phi", "vertices"};
    static const int dims[5] = {2, 2, 3, 3, 2};
    Py_buffer views[5];
    int got = 0;
    PyObject *result = NULL, *fast = NULL;
    double *work = NULL;
    for (; got < 5; got++)
        if (get_array(objs[got], &views[got], dims[got], 0, 0, names[got]) < 0) goto done;
    /* count centres of n coordinates, charts of dimension k (phi's last axis). */
    Py_ssize_t count = views[0].shape[0], n = views[0].shape[1];
    int k = (int)views[2].shape[2];
    if (check_k(k) < 0) goto done;
    const Py_ssize_t shapes[5][3] = {{count, n}, {count, n}, {count, n, k}, {count, n, k},
                                     {count, k}};
    for (int i = 1; i < 5; i++)
        if (check_shape(&views[i], dims[i], shapes[i], names[i]) < 0) goto done;
    fast = PySequence_Fast(polys, "polys must be a sequence of polytopes");
    if (fast == NULL) goto done;
    if (PySequence_Fast_GET_SIZE(fast) != count) {
        PyErr_Format(PyExc_ValueError, "%zd polytopes for %zd centres", PySequence_Fast_GET_SIZE(fast),
                     count);
        goto done;
    }
    for (Py_ssize_t q = 0; q < count; q++) {
        PyObject *p = PySequence_Fast_GET_ITEM(fast, q);
        if (!PyObject_TypeCheck(p, &PolytopeType) || ((Polytope *)p)->k != k) {
            PyErr_Format(PyExc_TypeError, "polys[%zd] is not a polytope of dimension %d", q, k);
            goto done;
        }
    }
    const double *x = views[0].buf, *xp = views[1].buf, *phi = views[2].buf,
                 *phip = views[3].buf, *verts = views[4].buf;
    size_t pairs = (size_t)(count * count);
    /* Per pair (p, q): the plane of new centre p in the chart of q's parent (u_pq . w <= b_pq),
     * its state (0 none, 1 cuts off q's vertex, 2 nearer than it), then per q the planes nearer
     * than its vertex (p ascending) and per p the tries whose vertex it cuts off. */
    size_t doubles = pairs * (size_t)(k + 1) + (size_t)(2 * k * k);
    work = PyMem_Malloc(sizeof(double) * doubles + sizeof(Py_ssize_t) * pairs +
                        (size_t)(3 * count + pairs));
    if (work == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    double *u = work, *b = u + pairs * k, *m = b + pairs, *g = m + k * k;
    Py_ssize_t *use = (Py_ssize_t *)(g + k * k);
    char *state = (char *)(use + pairs), *gone = state + pairs, *taken = gone + count;
    double small = tol * r, four_r2 = 4 * r * r;
    for (Py_ssize_t p = 0; p < count; p++) {
        for (Py_ssize_t q = 0; q < count; q++) {
            size_t pq = (size_t)(p * count + q);
            state[pq] = 0;
            if (p == q) continue;
            const double *base = phip + q * n * k;
            double dist2 = 0.0, bc = 0.0, reach = 0.0, vv = 0.0;
            double *uc = u + pq * k;
            for (int d = 0; d < k; d++) uc[d] = 0.0;
            for (Py_ssize_t j = 0; j < n; j++) {
                double e = x[p * n + j] - xp[q * n + j];
                dist2 += e * e;
                for (int d = 0; d < k; d++) uc[d] += e * base[j * k + d];
            }
            for (int d = 0; d < k; d++) {
                bc += uc[d] * uc[d];
                reach += uc[d] * verts[q * k + d];
                vv += verts[q * k + d] * verts[q * k + d];
            }
            bc *= 0.5;
            b[pq] = bc;
            if (!(dist2 < four_r2 && small < bc)) continue;
            if (!alike(phi + p * n * k, base, n, k, threshold, m, g)) continue;
            if (reach - bc > tol)
                state[pq] = 1;
            else if (0.5 * bc < vv) /* new vertices lie on the plane: only a nearer one can */
                state[pq] = 2;
        }
    }
    memset(gone, 0, (size_t)(2 * count));
    result = PyList_New(0);
    if (result == NULL) goto done;
    for (Py_ssize_t q = 0; q < count; q++) {
        if (gone[q]) continue;
        Py_ssize_t planes = 0;
        for (Py_ssize_t p = 0; p < count; p++)
            if (taken[p] && state[p * count + q] == 2) use[planes++] = p * count + q;
        if (planes) {
            int keep = still_picked((Polytope *)PySequence_Fast_GET_ITEM(fast, q), verts + q * k,
                                    u, b, use, planes, tol, r2);
            if (keep < 0) {
                Py_CLEAR(result);
                goto done;
            }
            if (!keep) continue;
        }
        PyObject *index = PyLong_FromSsize_t(q);
        if (index == NULL || PyList_Append(result, index) < 0) {
            Py_XDECREF(index);
            Py_CLEAR(result);
            goto done;
        }
        Py_DECREF(index);
        taken[q] = 1;
        for (Py_ssize_t later = 0; later < count; later++)
            if (state[q * count + later] == 1) gone[later] = 1;
    }
done:
    PyMem_Free(work);
    Py_XDECREF(fast);
    for (int i = 0; i < got; i++) PyBuffer_Release(&views[i]);
    return result;
}


/* -- signs and singular values of a wave's small matrices (projection.py) --------------------
 *
 * A wave asks these of a few dozen matrices of size k x k or n x n at a time; numpy.linalg
 * costs 10-30 us per call for its LAPACK dispatch, several times the arithmetic. Only signs and
 * a threshold test on a singular value are read, so LAPACK's own doubles are not needed. */

/* The stack (B, rows, cols) and its output (B,), checked: 0, or -1 with an exception. */
static int get_stack(PyObject *const *args, Py_ssize_t nargs, const char *name, int square,
                     Py_buffer *in, Py_buffer *out) {
    if (nargs != 2) {
        PyErr_Format(PyExc_TypeError, "%s(a, out) takes 2 arguments", name);
        return -1;
    }
    if (get_array(args[0], in, 3, 0, 0, "a") < 0) return -1;
    if (get_array(args[1], out, 1, 0, 1, "out") < 0) {
        PyBuffer_Release(in);
        return -1;
    }
    const Py_ssize_t out_shape[1] = {in->shape[0]};
    if (square && in->shape[1] != in->shape[2])
        PyErr_Format(PyExc_ValueError, "a: expected a stack of square matrices (B, n, n), got "
                     "(%zd, %zd, %zd)", in->shape[0], in->shape[1], in->shape[2]);
    if (PyErr_Occurred() || check_shape(out, 1, out_shape, "out") < 0) {
        PyBuffer_Release(in);
        PyBuffer_Release(out);
        return -1;
    }
    return 0;
}

/* Sign of det(a) (n x n, destroyed) by Gaussian elimination with partial pivoting: 1, -1, or 0
 * when a pivot column is zero (numpy.linalg.slogdet's sign). */
static double det_sign(double *a, Py_ssize_t n) {
    double sign = 1.0;
    for (Py_ssize_t c = 0; c < n; c++) {
        Py_ssize_t pivot = c;
        for (Py_ssize_t r = c + 1; r < n; r++)
            if (fabs(a[r * n + c]) > fabs(a[pivot * n + c])) pivot = r;
        double head = a[pivot * n + c];
        if (head == 0.0) return 0.0;
        if (pivot != c) {
            for (Py_ssize_t j = c; j < n; j++) {
                double t = a[c * n + j];
                a[c * n + j] = a[pivot * n + j];
                a[pivot * n + j] = t;
            }
            sign = -sign;
        }
        if (head < 0.0) sign = -sign;
        for (Py_ssize_t r = c + 1; r < n; r++) {
            double f = a[r * n + c] / head;
            for (Py_ssize_t j = c + 1; j < n; j++) a[r * n + j] -= f * a[c * n + j];
        }
    }
    return sign;
}

static PyObject *det_signs(PyObject *mod, PyObject *const *args, Py_ssize_t nargs) {
    Py_buffer in, out;
    if (get_stack(args, nargs, "det_signs", 1, &in, &out) < 0) return NULL;
    Py_ssize_t count = in.shape[0], n = in.shape[1];
    double *work = PyMem_Malloc(sizeof(double) * (size_t)(n * n > 0 ? n * n : 1));
    if (work == NULL) {
        PyBuffer_Release(&in);
        PyBuffer_Release(&out);
        return PyErr_NoMemory();
    }
    const double *a = in.buf;
    double *sign = out.buf;
    for (Py_ssize_t b = 0; b < count; b++) {
        memcpy(work, a + b * n * n, sizeof(double) * (size_t)(n * n));
        sign[b] = det_sign(work, n);
    }
    PyMem_Free(work);
    PyBuffer_Release(&in);
    PyBuffer_Release(&out);
    Py_RETURN_NONE;
}

static PyObject *min_singular_values(PyObject *mod, PyObject *const *args, Py_ssize_t nargs) {
    Py_buffer in, out;
    if (get_stack(args, nargs, "min_singular_values", 0, &in, &out) < 0) return NULL;
    Py_ssize_t count = in.shape[0], rows = in.shape[1], k = in.shape[2];
    if (rows < k || k < 1) {
        PyErr_Format(PyExc_ValueError, "min_singular_values needs rows >= cols >= 1, got %zd x %zd",
                     rows, k);
        PyBuffer_Release(&in);
        PyBuffer_Release(&out);
        return NULL;
    }
    double *g = PyMem_Malloc(sizeof(double) * (size_t)(k * k));
    if (g == NULL) {
        PyBuffer_Release(&in);
        PyBuffer_Release(&out);
        return PyErr_NoMemory();
    }
    const double *a = in.buf;
    double *sigma = out.buf;
    for (Py_ssize_t b = 0; b < count; b++) {
        const double *m = a + b * rows * k;
        for (Py_ssize_t i = 0; i < k; i++) { /* g = m^T m */
            for (Py_ssize_t j = 0; j < k; j++) {
                double s = 0.0;
                for (Py_ssize_t r = 0; r < rows; r++) s += m[r * k + i] * m[r * k + j];
                g[i * k + j] = s;
            }
        }
        double lambda = min_eigenvalue(g, k);
        sigma[b] = lambda > 0.0 ? sqrt(lambda) : 0.0;
    }
    PyMem_Free(g);
    PyBuffer_Release(&in);
    PyBuffer_Release(&out);
    Py_RETURN_NONE;
}

static PyMethodDef module_methods[] = {
    {"compatible", compatible, METH_VARARGS,
     "compatible(polys, centres, parent_centres, phi, parent_phi, vertices, r, r2, tol, "
     "threshold): the tries a wave can add together, in order (see polytope.py)."},
    {"det_signs", (PyCFunction)(void (*)(void))det_signs, METH_FASTCALL,
     "det_signs(a, out): out[b] = sign(det(a[b])) (1, -1 or 0) for a stack a (B, n, n)."},
    {"min_singular_values", (PyCFunction)(void (*)(void))min_singular_values, METH_FASTCALL,
     "min_singular_values(a, out): out[b] = smallest singular value of a[b], a (B, rows, k)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT,
    .m_name = "sahgrasp.atlas._polytope",
    .m_doc = "Compiled chart polytopes and small dense kernels of the atlas builder.",
    .m_size = -1,
    .m_methods = module_methods,
};

PyMODINIT_FUNC PyInit__polytope(void) {
    static PyTypeObject *types[] = {&PolytopeType, NULL};
    static const IntConstant constants[] = {{"MAX_FACES", MAX_FACES}, {NULL, 0}};
    return create_module(&module, types, constants);
}

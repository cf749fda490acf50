/* The auto method's Levenberg-Marquardt loop in one native call (docs/methods/ik.md, "The compiled loop").
 *
 * A Tree holds a hand's kinematic tree as exported from its Pinocchio model by sahgrasp/ik/compiled.py:
 * a free-flyer root (the wrist) and 1-DoF revolute or prismatic joints, mimic joints included
 * (a joint's value is scale * q[q_index] + offset). It evaluates the contact stack (p_i, r_i) of
 * the IK, its Jacobian with respect to v, Pinocchio's integration q (+) v, and the whole loop of
 * sahgrasp/ik/solver.py's `_lm_loop`. In Python on Pinocchio the unavoidable calls of one
 * iteration alone cost several times the whole compiled iteration, which is a few microseconds
 * of arithmetic (docs/methods/ik.md, "The compiled loop").
 *
 * Rotations are row-major 3 x 3. Buffers are C-contiguous float64 (int64 for finger indices).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <structmember.h>
#include <stddef.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../_arrays.h"
#include "../collision/_gjk.h"

typedef struct {
    double R[9];
    double t[3];
} Pose;

typedef struct {
    PyObject_HEAD
    int nj;          /* joints, the root first (Pinocchio's joints 1..njoints-1) */
    int nq, nv, nf;  /* configuration and velocity sizes, fingers */
    int *parent;     /* index of the parent joint, -1 for the root */
    Pose *place;     /* placement of each joint in its parent */
    double *axis;    /* unit axis in the joint frame, 3 per joint (unused for the root) */
    int *prismatic;  /* 1 for a prismatic joint, 0 for a revolute one */
    int *q_index, *v_index;
    double *scale, *offset;
    int *yaw;        /* per finger, the joint whose frame is the contact frame's parent */
    int *chain;      /* per finger, the non-root joints moving its yaw joint, nj per finger */
    int *chain_len;
    int *columns;    /* per finger, the columns of v that move it (ascending), nv per finger */
    int *columns_len;
    double radius;   /* fingertip sphere radius [m] */
    double *lower, *upper;  /* limits of q[7:] */
    /* Collision shapes (set_shapes), for the self-collision verdicts; none until set. */
    int ns, npairs;
    int *shape_joint;     /* tree joint carrying each shape */
    Pose *shape_place;    /* each shape's placement in its joint's frame */
    GjkShape *shapes;     /* kind, size, inflation; placed per query */
    double *ball;         /* bounding ball per shape: local centre, radius (4 values) */
    int *pairs;           /* the checked pairs, 2 shape indices each */
} Tree;

/* ---------------------------------------------------------------- small linear algebra -- */

static void compose(const Pose *a, const Pose *b, Pose *out) {
    Pose r;
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++)
            r.R[3 * i + j] = a->R[3 * i] * b->R[j] + a->R[3 * i + 1] * b->R[3 + j] +
                             a->R[3 * i + 2] * b->R[6 + j];
        r.t[i] = a->R[3 * i] * b->t[0] + a->R[3 * i + 1] * b->t[1] + a->R[3 * i + 2] * b->t[2] +
                 a->t[i];
    }
    *out = r;
}

/* The motion of a 1-DoF joint by `value` (rad or m) about / along the unit `axis`. */
static void joint_motion(const double *axis, int prismatic, double value, Pose *out) {
    memset(out, 0, sizeof(Pose));
    if (prismatic) {
        out->R[0] = out->R[4] = out->R[8] = 1.0;
        for (int i = 0; i < 3; i++) out->t[i] = axis[i] * value;
        return;
    }
    double s = sin(value), c = cos(value), v = 1.0 - c;
    double x = axis[0], y = axis[1], z = axis[2];
    out->R[0] = c + x * x * v;
    out->R[1] = x * y * v - z * s;
    out->R[2] = x * z * v + y * s;
    out->R[3] = y * x * v + z * s;
    out->R[4] = c + y * y * v;
    out->R[5] = y * z * v - x * s;
    out->R[6] = z * x * v - y * s;
    out->R[7] = z * y * v + x * s;
    out->R[8] = c + z * z * v;
}

/* Rotation of the unit quaternion (x, y, z, w). */
static void quat_rotation(const double *q, double *R) {
    double x = q[0], y = q[1], z = q[2], w = q[3];
    R[0] = 1.0 - 2.0 * (y * y + z * z);
    R[1] = 2.0 * (x * y - z * w);
    R[2] = 2.0 * (x * z + y * w);
    R[3] = 2.0 * (x * y + z * w);
    R[4] = 1.0 - 2.0 * (x * x + z * z);
    R[5] = 2.0 * (y * z - x * w);
    R[6] = 2.0 * (x * z - y * w);
    R[7] = 2.0 * (y * z + x * w);
    R[8] = 1.0 - 2.0 * (x * x + y * y);
}

static void cross(const double *a, const double *b, double *out) {
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

/* -------------------------------------------------------------------------- kinematics -- */

/* World placements of every joint at q (Pinocchio's data.oMi[1:]). */
static void forward(const Tree *T, const double *q, Pose *M) {
    Pose wrist;
    quat_rotation(q + 3, wrist.R);
    memcpy(wrist.t, q, 3 * sizeof(double));
    compose(&T->place[0], &wrist, &M[0]);
    for (int j = 1; j < T->nj; j++) {
        Pose motion, local;
        joint_motion(T->axis + 3 * j, T->prismatic[j],
                     T->scale[j] * q[T->q_index[j]] + T->offset[j], &motion);
        compose(&T->place[j], &motion, &local);
        compose(&M[T->parent[j]], &local, &M[j]);
    }
}

/* The contact stack (p_i, r_i) of `fingers` from the placements: the yaw joint's x axis is the
 * outward normal n_i, its origin the sphere centre r_i, and p_i = r_i + radius n_i. */
static void stack_of(const Tree *T, const Pose *M, const long long *fingers, int nf, double *s) {
    for (int b = 0; b < nf; b++) {
        const Pose *Y = &M[T->yaw[fingers[b]]];
        for (int i = 0; i < 3; i++) {
            s[6 * b + i] = Y->t[i] + T->radius * Y->R[3 * i];
            s[6 * b + 3 + i] = Y->t[i];
        }
    }
}

/* Columns c and 3 + c of the Jacobian of the world point x: the velocity of x per unit of the
 * wrist's local linear (col) and angular (m) velocity along its axis c. */
static void wrist_columns(const Pose *W, const double *x, int c, double *col, double *m) {
    double d[3] = {x[0] - W->t[0], x[1] - W->t[1], x[2] - W->t[2]};
    col[0] = W->R[c], col[1] = W->R[3 + c], col[2] = W->R[6 + c];
    cross(col, d, m);
}

/* The velocity of the world point x per unit velocity of joint k (before a mimic's scale). */
static void joint_velocity(const Tree *T, const Pose *M, int k, const double *x, double *m) {
    const Pose *K = &M[k];
    const double *u = T->axis + 3 * k;
    double a[3];
    for (int i = 0; i < 3; i++)
        a[i] = K->R[3 * i] * u[0] + K->R[3 * i + 1] * u[1] + K->R[3 * i + 2] * u[2];
    if (T->prismatic[k]) {
        memcpy(m, a, sizeof a);
    } else {
        double e[3] = {x[0] - K->t[0], x[1] - K->t[1], x[2] - K->t[2]};
        cross(a, e, m);
    }
}

/* Jacobian (6 nf x nv, row-major) of the stack with respect to v at the placements M. The root's
 * columns are Pinocchio's free-flyer velocity (linear, angular) in the wrist frame; a mimic
 * joint adds its scaled column to its leader's. */
static void jacobian_of(const Tree *T, const Pose *M, const long long *fingers, int nf,
                        const double *stack, double *J) {
    int nv = T->nv;
    memset(J, 0, (size_t)(6 * nf * nv) * sizeof(double));
    const Pose *W = &M[0];
    for (int b = 0; b < nf; b++) {
        int f = (int)fingers[b];
        for (int half = 0; half < 2; half++) {
            const double *x = stack + 6 * b + 3 * half;
            double *rows = J + (size_t)(6 * b + 3 * half) * nv;
            for (int c = 0; c < 3; c++) {
                double col[3], m[3];
                wrist_columns(W, x, c, col, m);
                for (int i = 0; i < 3; i++) {
                    rows[i * nv + c] = col[i];
                    rows[i * nv + 3 + c] = m[i];
                }
            }
            for (int n = 0; n < T->chain_len[f]; n++) {
                int k = T->chain[f * T->nj + n];
                double m[3];
                joint_velocity(T, M, k, x, m);
                for (int i = 0; i < 3; i++) rows[i * nv + T->v_index[k]] += T->scale[k] * m[i];
            }
        }
    }
}

/* q (+) v on the free flyer's Lie group (M exp6(v), quaternion renormalised) and on the joints,
 * then the joints clamped to their limits. */
static void integrate_clamped(const Tree *T, const double *q, const double *v, double *out,
                              int clamp) {
    const double *w = v + 3;
    double th2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2], th = sqrt(th2);
    double half_sin, B, C;  /* sin(th/2)/th, (1-cos th)/th^2, (th - sin th)/th^3 */
    if (th < 1e-4) {
        half_sin = 0.5 - th2 / 48.0;
        B = 0.5 - th2 / 24.0;
        C = 1.0 / 6.0 - th2 / 120.0;
    } else {
        half_sin = sin(0.5 * th) / th;
        B = (1.0 - cos(th)) / th2;
        C = (th - sin(th)) / (th2 * th);
    }
    double wv[3], wwv[3], Vv[3], R[9];
    cross(w, v, wv);
    cross(w, wv, wwv);
    for (int i = 0; i < 3; i++) Vv[i] = v[i] + B * wv[i] + C * wwv[i];
    quat_rotation(q + 3, R);
    for (int i = 0; i < 3; i++)
        out[i] = q[i] + R[3 * i] * Vv[0] + R[3 * i + 1] * Vv[1] + R[3 * i + 2] * Vv[2];
    double ex = half_sin * w[0], ey = half_sin * w[1], ez = half_sin * w[2];
    double ew = th < 1e-4 ? 1.0 - th2 / 8.0 : cos(0.5 * th);
    double x = q[3], y = q[4], z = q[5], s = q[6];
    double qx = s * ex + x * ew + y * ez - z * ey;
    double qy = s * ey - x * ez + y * ew + z * ex;
    double qz = s * ez + x * ey - y * ex + z * ew;
    double qw = s * ew - x * ex - y * ey - z * ez;
    double norm = sqrt(qx * qx + qy * qy + qz * qz + qw * qw);
    out[3] = qx / norm;
    out[4] = qy / norm;
    out[5] = qz / norm;
    out[6] = qw / norm;
    for (int i = 0; i < T->nq - 7; i++) {
        double value = q[7 + i] + v[6 + i];
        if (clamp) {
            if (value < T->lower[i]) value = T->lower[i];
            if (value > T->upper[i]) value = T->upper[i];
        }
        out[7 + i] = value;
    }
}

/* ---------------------------------------------------------------------- the LM loop -- */

/* Solve (A + mu I) x = g by Cholesky (A's lower triangle read); 0 if A + mu I is not positive
 * definite. Right-looking: each column updates the trailing rows with independent operations,
 * which pipeline, where the dot-product form waits on one long chain of additions per entry. */
static int damped_solve(const double *A, const double *g, double mu, int n, double *L,
                        double *x) {
    for (int i = 0; i < n; i++) {
        memcpy(L + i * n, A + i * n, (size_t)(i + 1) * sizeof(double));
        L[i * n + i] += mu;
    }
    for (int j = 0; j < n; j++) {
        double d = L[j * n + j];
        if (!(d > 0.0)) return 0;
        d = sqrt(d);
        L[j * n + j] = d;
        for (int i = j + 1; i < n; i++) L[i * n + j] /= d;
        for (int i = j + 1; i < n; i++) {
            double lij = L[i * n + j];
            for (int k = j + 1; k <= i; k++) L[i * n + k] -= lij * L[k * n + j];
        }
    }
    for (int i = 0; i < n; i++) {
        double sum = g[i];
        for (int k = 0; k < i; k++) sum -= L[i * n + k] * x[k];
        x[i] = sum / L[i * n + i];
    }
    for (int i = n - 1; i >= 0; i--) {
        double sum = x[i];
        for (int k = i + 1; k < n; k++) sum -= L[k * n + i] * x[k];
        x[i] = sum / L[i * n + i];
    }
    return 1;
}

static double dot(const double *a, const double *b, int n) {
    double s = 0.0;
    for (int i = 0; i < n; i++) s += a[i] * b[i];
    return s;
}

/* Largest contact-point or centre error [m] of a stacked residual (3-blocks). */
static double max_error(const double *r, int m) {
    double worst = 0.0;
    for (int i = 0; i < m; i += 3) {
        double e = r[i] * r[i] + r[i + 1] * r[i + 1] + r[i + 2] * r[i + 2];
        if (e > worst) worst = e;
    }
    return sqrt(worst);
}

enum { CONVERGED = 0, NO_PROGRESS = 1, MAX_ITERATIONS = 2 };

/* The tree's joints are numbered from 0, the root (the wrist); the fixed world, the root's
 * parent and the body of a hand-object contact's object, is joint FIXED_JOINT. */
enum { FIXED_JOINT = -1 };

typedef struct {
    const Tree *T;
    const long long *fingers;
    int nf, m, nv;
    const double *target;
    Pose *M;
    double *stack, *J, *r, *g, *A, *L, *x, *step, *cand, *r_new, *costs;
    int *free_cols, *position; /* the free columns; per column its place among them, or -1 */
} Work;

/* residual = target - stack of q's placements (M must hold them); returns its cost. */
static double residual_of(Work *w, const double *q, double *stack, double *r) {
    forward(w->T, q, w->M);
    stack_of(w->T, w->M, w->fingers, w->nf, stack);
    for (int i = 0; i < w->m; i++) r[i] = w->target[i] - stack[i];
    return dot(r, r, w->m);
}

/* Whether column c is fixed: a joint at a bound with the gradient g pushing it outwards. */
static int fixed_at_bound(const Tree *T, const double *q, int c, double g) {
    if (c < 6) return 0; /* the wrist is free */
    double value = q[c + 1], lo = T->lower[c - 6] + 1e-12, hi = T->upper[c - 6] - 1e-12;
    return (value <= lo && g < 0.0) || (value >= hi && g > 0.0);
}

/* Active set: the free columns (at a bound with the gradient pushing outwards = fixed). */
static int free_columns(const Work *w, const double *q) {
    int n = 0;
    for (int c = 0; c < w->nv; c++) {
        w->position[c] = -1;
        if (fixed_at_bound(w->T, q, c, w->g[c])) continue;
        w->position[c] = n;
        w->free_cols[n++] = c;
    }
    return n;
}

/* g = J^T r and the lower triangle of A = J_F^T J_F, finger by finger on the columns that move
 * each finger (a finger's rows are zero elsewhere: about a fifth of the dense products). */
static void gradient(Work *w) {
    int nv = w->nv;
    memset(w->g, 0, (size_t)nv * sizeof(double));
    for (int b = 0; b < w->nf; b++) {
        int f = (int)w->fingers[b];
        const int *cols = w->T->columns + f * nv;
        for (int a = 0; a < w->T->columns_len[f]; a++) {
            double s = 0.0;
            for (int i = 6 * b; i < 6 * b + 6; i++) s += w->J[i * nv + cols[a]] * w->r[i];
            w->g[cols[a]] += s;
        }
    }
}

static void gram(Work *w, int n) {
    int nv = w->nv;
    memset(w->A, 0, (size_t)n * n * sizeof(double));
    for (int b = 0; b < w->nf; b++) {
        int f = (int)w->fingers[b];
        const int *cols = w->T->columns + f * nv;
        for (int u = 0; u < w->T->columns_len[f]; u++) {
            int pu = w->position[cols[u]];
            if (pu < 0) continue;
            for (int v = 0; v <= u; v++) {
                int pv = w->position[cols[v]];
                if (pv < 0) continue;
                double s = 0.0;
                for (int i = 6 * b; i < 6 * b + 6; i++)
                    s += w->J[i * nv + cols[u]] * w->J[i * nv + cols[v]];
                w->A[pu * n + pv] += s;
            }
        }
    }
}

/* One Marquardt step from q with damping adapted until the cost decreases: 1 and the new
 * configuration in w->cand (its residual in w->r_new, its stack in w->stack), or 0 if the damping
 * ran out. */
static int damped_step(Work *w, const double *q, double cost, double *damping) {
    int m = w->m, nv = w->nv;
    gradient(w);
    int n = free_columns(w, q);
    gram(w, n);
    for (int a = 0; a < n; a++) w->g[a] = w->g[w->free_cols[a]]; /* free_cols ascend: in place */
    double *cand_stack = w->step + nv;
    while (*damping <= 1e4) {
        if (damped_solve(w->A, w->g, *damping, n, w->L, w->x)) {
            memset(w->step, 0, (size_t)nv * sizeof(double));
            for (int a = 0; a < n; a++) w->step[w->free_cols[a]] = w->x[a];
            integrate_clamped(w->T, q, w->step, w->cand, 1);
            if (residual_of(w, w->cand, cand_stack, w->r_new) < cost) {
                memcpy(w->stack, cand_stack, (size_t)m * sizeof(double));
                *damping = *damping / 3.0 > 1e-7 ? *damping / 3.0 : 1e-7;
                return 1;
            }
        }
        *damping *= 4.0;
    }
    return 0;
}

typedef struct {
    int outcome, iterations;
    double error;
} Outcome;

/* sahgrasp/ik/solver.py's loop: Levenberg-Marquardt on the stacked contacts, free wrist, bounds
 * as an active set, early abandonment, refinement to refine_m. q is updated in place; `history`
 * (or NULL) is called after every accepted step. Returns 0, or -1 on a Python error (from
 * history). */
static int lm_loop(Work *w, double *q, int max_iterations, double refine_m, double d_min_m,
                   int stall, PyObject *history, Outcome *out) {
    int m = w->m, nq = w->T->nq;
    double damping = 1e-3, *costs = w->costs;
    int ncosts = 0;
    costs[ncosts++] = residual_of(w, q, w->stack, w->r);
    jacobian_of(w->T, w->M, w->fingers, w->nf, w->stack, w->J);
    double refine_cost = (double)(m / 3) * refine_m * refine_m;
    for (int k = 0; k < max_iterations; k++) {
        double cost = costs[ncosts - 1], error;
        if (cost < refine_cost && (error = max_error(w->r, m)) < refine_m) {
            *out = (Outcome){CONVERGED, k, error};
            return 0;
        }
        int stalled = ncosts > stall && cost > 0.5 * costs[ncosts - 1 - stall];
        if (stalled || damping > 1e4) {
            error = max_error(w->r, m);
            *out = (Outcome){error < d_min_m ? CONVERGED : NO_PROGRESS, k, error};
            return 0;
        }
        if (!damped_step(w, q, cost, &damping)) continue;
        memcpy(q, w->cand, (size_t)nq * sizeof(double));
        memcpy(w->r, w->r_new, (size_t)m * sizeof(double));
        if (history != NULL) {
            PyObject *res = PyObject_CallNoArgs(history);
            if (res == NULL) return -1;
            Py_DECREF(res);
        }
        /* The candidate's placements are still in w->M: only the Jacobian is new. */
        jacobian_of(w->T, w->M, w->fingers, w->nf, w->stack, w->J);
        costs[ncosts++] = dot(w->r, w->r, m);
    }
    double error = max_error(w->r, m);
    *out = (Outcome){error < d_min_m ? CONVERGED : MAX_ITERATIONS, max_iterations, error};
    return 0;
}

/* ------------------------------------------------------------------- Python interface -- */

/* 0 if ``kwds`` holds every name of ``kwlist`` (a type's keyword-only arguments, all
 * required), or -1 with a TypeError naming the first one missing. */
static int missing_keyword(const char *type, char **kwlist, PyObject *kwds) {
    for (char **name = kwlist; *name != NULL; name++) {
        PyObject *value = kwds == NULL ? NULL : PyDict_GetItemString(kwds, *name);
        if (value == NULL) {
            PyErr_Format(PyExc_TypeError, "%s() missing required keyword argument '%s'", type,
                         *name);
            return -1;
        }
    }
    return 0;
}

static void Tree_dealloc(Tree *self) {
    PyMem_Free(self->parent);
    PyMem_Free(self->place);
    PyMem_Free(self->axis);
    PyMem_Free(self->prismatic);
    PyMem_Free(self->q_index);
    PyMem_Free(self->v_index);
    PyMem_Free(self->scale);
    PyMem_Free(self->offset);
    PyMem_Free(self->yaw);
    PyMem_Free(self->chain);
    PyMem_Free(self->chain_len);
    PyMem_Free(self->columns);
    PyMem_Free(self->columns_len);
    PyMem_Free(self->lower);
    PyMem_Free(self->upper);
    PyMem_Free(self->shape_joint);
    PyMem_Free(self->shape_place);
    PyMem_Free(self->shapes);
    PyMem_Free(self->ball);
    PyMem_Free(self->pairs);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static int Tree_init(Tree *self, PyObject *args, PyObject *kwds) {
    static char *kwlist[] = {"parents", "placements", "axes", "prismatic", "q_index", "v_index",
                             "scale", "offset", "yaw", "radius", "lower", "upper", "nq", "nv",
                             NULL};
    PyObject *o[11];
    double radius = 0.0;
    int nq = 0, nv = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "|$OOOOOOOOOdOOii", kwlist, &o[0], &o[1], &o[2],
                                     &o[3], &o[4], &o[5], &o[6], &o[7], &o[8], &radius, &o[9],
                                     &o[10], &nq, &nv) ||
        missing_keyword("Tree", kwlist, kwds) < 0)
        return -1;
    if (self->parent != NULL) {
        PyErr_SetString(PyExc_RuntimeError, "Tree is already initialised");
        return -1;
    }
    Py_buffer b[11];
    int got = 0, status = -1;
    const char *names[11] = {"parents", "placements", "axes", "prismatic", "q_index", "v_index",
                             "scale", "offset", "yaw", "lower", "upper"};
    const char *formats[11] = {"q", "d", "d", "q", "q", "q", "d", "d", "q", "d", "d"};
    for (; got < 11; got++)
        if (get_items(o[got], &b[got], -1, formats[got][0] == 'q', 0, names[got]) < 0) goto out;
    Py_ssize_t nj = b[0].len / 8, nf = b[8].len / 8;
    if (nj < 1 || nf < 1 || nq < 7 || nv != nq - 1) {
        PyErr_Format(PyExc_ValueError, "Tree: expected at least one joint in parents (got %zd), "
                     "one finger in yaw (got %zd), nq >= 7 (got %d) and nv = nq - 1 (got %d)",
                     nj, nf, nq, nv);
        goto out;
    }
    /* Values per joint of placements .. offset, per actuated coordinate of lower and upper. */
    const Py_ssize_t expected[11] = {nj, 12 * nj, 3 * nj, nj, nj, nj, nj, nj, nf, nq - 7, nq - 7};
    for (int k = 1; k < 11; k++)
        if (b[k].len != expected[k] * 8) {
            PyErr_Format(PyExc_ValueError, "Tree: %s: expected %zd values, got %zd", names[k],
                         expected[k], b[k].len / 8);
            goto out;
        }
    const long long *parents = b[0].buf, *prismatic = b[3].buf, *qi = b[4].buf, *vi = b[5].buf,
                    *yaw = b[8].buf;
    for (Py_ssize_t j = 0; j < nj; j++) {
        int bad_parent = j == 0 ? parents[0] != FIXED_JOINT : (parents[j] < 0 || parents[j] >= j);
        int bad_index = j > 0 && (qi[j] < 7 || qi[j] >= nq || vi[j] < 6 || vi[j] >= nv);
        if (bad_parent) {
            PyErr_Format(PyExc_ValueError, "Tree: parents[%zd] = %lld: expected %s", j,
                         parents[j], j == 0 ? "FIXED_JOINT (-1) for the root"
                                            : "an earlier joint (0 to its own index - 1)");
            goto out;
        }
        if (bad_index) {
            PyErr_Format(PyExc_ValueError, "Tree: q_index[%zd] = %lld, v_index[%zd] = %lld: "
                         "expected 7 to nq - 1 = %d and 6 to nv - 1 = %d", j, qi[j], j, vi[j],
                         nq - 1, nv - 1);
            goto out;
        }
    }
    for (Py_ssize_t f = 0; f < nf; f++)
        if (yaw[f] < 1 || yaw[f] >= nj) {
            PyErr_Format(PyExc_ValueError, "Tree: yaw[%zd] = %lld: expected a finger joint, 1 to "
                         "%zd", f, yaw[f], nj - 1);
            goto out;
        }
    self->nj = (int)nj;
    self->nq = nq;
    self->nv = nv;
    self->nf = (int)nf;
    self->radius = radius;
    self->parent = PyMem_Malloc(nj * sizeof(int));
    self->place = PyMem_Malloc(nj * sizeof(Pose));
    self->axis = PyMem_Malloc(nj * 3 * sizeof(double));
    self->prismatic = PyMem_Malloc(nj * sizeof(int));
    self->q_index = PyMem_Malloc(nj * sizeof(int));
    self->v_index = PyMem_Malloc(nj * sizeof(int));
    self->scale = PyMem_Malloc(nj * sizeof(double));
    self->offset = PyMem_Malloc(nj * sizeof(double));
    self->yaw = PyMem_Malloc(nf * sizeof(int));
    self->chain = PyMem_Malloc(nf * nj * sizeof(int));
    self->chain_len = PyMem_Malloc(nf * sizeof(int));
    self->columns = PyMem_Malloc(nf * nv * sizeof(int));
    self->columns_len = PyMem_Malloc(nf * sizeof(int));
    self->lower = PyMem_Malloc((nq - 7) * sizeof(double));
    self->upper = PyMem_Malloc((nq - 7) * sizeof(double));
    if (!self->parent || !self->place || !self->axis || !self->prismatic || !self->q_index ||
        !self->v_index || !self->scale || !self->offset || !self->yaw || !self->chain ||
        !self->chain_len || !self->columns || !self->columns_len || !self->lower || !self->upper) {
        PyErr_NoMemory();
        goto out;
    }
    const double *placements = b[1].buf;
    for (Py_ssize_t j = 0; j < nj; j++) {
        self->parent[j] = (int)parents[j];
        memcpy(self->place[j].R, placements + 12 * j, 9 * sizeof(double));
        memcpy(self->place[j].t, placements + 12 * j + 9, 3 * sizeof(double));
        self->prismatic[j] = prismatic[j] != 0;
        self->q_index[j] = (int)qi[j];
        self->v_index[j] = (int)vi[j];
    }
    memcpy(self->axis, b[2].buf, nj * 3 * sizeof(double));
    memcpy(self->scale, b[6].buf, nj * sizeof(double));
    memcpy(self->offset, b[7].buf, nj * sizeof(double));
    memcpy(self->lower, b[9].buf, (nq - 7) * sizeof(double));
    memcpy(self->upper, b[10].buf, (nq - 7) * sizeof(double));
    for (Py_ssize_t f = 0; f < nf; f++) {
        int n = 0;
        self->yaw[f] = (int)yaw[f];
        for (int j = self->yaw[f]; j > 0; j = self->parent[j]) self->chain[f * nj + n++] = j;
        self->chain_len[f] = n;
        int *cols = self->columns + f * nv, count = 0;
        for (int c = 0; c < nv; c++) {
            int moves = c < 6;
            for (int k = 0; k < n && !moves; k++) moves = self->v_index[self->chain[f * nj + k]] == c;
            if (moves) cols[count++] = c;
        }
        self->columns_len[f] = count;
    }
    status = 0;
out:
    while (got-- > 0) PyBuffer_Release(&b[got]);
    return status;
}

static int check_ready(const Tree *self) {
    if (self->parent == NULL) {
        PyErr_SetString(PyExc_RuntimeError, "Tree is not initialised");
        return -1;
    }
    return 0;
}

static void work_free(Work *w) {
    PyMem_Free(w->M);
    PyMem_Free(w->stack);
    PyMem_Free(w->free_cols);
    PyMem_Free(w->position);
}

/* Buffers of one call (the costs of up to `iterations` steps), one allocation for the doubles. */
/* 0 if every finger index is one of the tree's, else -1 with a ValueError. */
static int check_fingers(const Tree *T, const long long *fingers, int nf) {
    for (int b = 0; b < nf; b++)
        if (fingers[b] < 0 || fingers[b] >= T->nf) {
            PyErr_Format(PyExc_ValueError, "fingers[%d] = %lld: finger index out of range 0 to "
                         "%d", b, fingers[b], T->nf - 1);
            return -1;
        }
    return 0;
}

/* The contact stack (p_i, r_i) of `fingers` at q into `stack` (6 nf values), without the loop's
 * buffers: 0, or -1 with an exception. */
static int stack_at(const Tree *T, const double *q, const long long *fingers, int nf,
                    double *stack) {
    if (check_fingers(T, fingers, nf) < 0) return -1;
    Pose *M = PyMem_Malloc((size_t)T->nj * sizeof(Pose));
    if (M == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    forward(T, q, M);
    stack_of(T, M, fingers, nf, stack);
    PyMem_Free(M);
    return 0;
}

static int work_init(Work *w, const Tree *T, const long long *fingers, int nf,
                     const double *target, int iterations) {
    int m = 6 * nf, nv = T->nv;
    memset(w, 0, sizeof(Work));
    if (check_fingers(T, fingers, nf) < 0) return -1;
    *w = (Work){.T = T, .fingers = fingers, .nf = nf, .m = m, .nv = nv, .target = target};
    size_t doubles = (size_t)m * 4 + (size_t)m * nv + (size_t)nv * (2 * nv + 3) + T->nq +
                     (size_t)iterations + 1;
    w->M = PyMem_Malloc((size_t)T->nj * sizeof(Pose));
    w->stack = PyMem_Malloc(doubles * sizeof(double));
    w->free_cols = PyMem_Malloc((size_t)nv * sizeof(int));
    w->position = PyMem_Malloc((size_t)nv * sizeof(int));
    if (!w->M || !w->stack || !w->free_cols || !w->position) {
        work_free(w);
        PyErr_NoMemory();
        return -1;
    }
    double *p = w->stack + m;
    w->r = p, p += m;
    w->r_new = p, p += m;
    w->J = p, p += (size_t)m * nv;
    w->g = p, p += nv;
    w->A = p, p += (size_t)nv * nv;
    w->L = p, p += (size_t)nv * nv;
    w->x = p, p += nv;
    w->step = p, p += nv + m; /* the step, then a candidate's stack */
    w->cand = p, p += T->nq;
    w->costs = p;
    return 0;
}

/* The buffers of a call on (q, fingers, a 6 nf vector): fingers, q, vector, in b[0..2]; 0, or -1
 * with an exception and nothing held. */
static int take_finger_buffers(const Tree *self, PyObject *q_obj, int q_writable,
                               PyObject *fingers_obj, PyObject *vec_obj, int vec_writable,
                               const char *vec_name, Py_buffer b[3], int *nf) {
    if (check_ready(self) < 0) return -1;
    if (get_items(fingers_obj, &b[0], -1, 1, 0, "fingers") < 0) return -1;
    *nf = (int)(b[0].len / 8);
    if (get_items(q_obj, &b[1], self->nq, 0, q_writable, "q") < 0) {
        PyBuffer_Release(&b[0]);
        return -1;
    }
    if (get_items(vec_obj, &b[2], 6 * *nf, 0, vec_writable, vec_name) < 0) {
        PyBuffer_Release(&b[1]);
        PyBuffer_Release(&b[0]);
        return -1;
    }
    return 0;
}

static void release_buffers(Py_buffer *b, int n) {
    for (int i = 0; i < n; i++) PyBuffer_Release(&b[i]);
}

static PyObject *Tree_solve(Tree *self, PyObject *args) {
    PyObject *q_obj, *target_obj, *fingers_obj, *history;
    int max_iterations, stall;
    double refine_m, d_min_m;
    PyObject *iterations_obj, *stall_obj;
    if (!PyArg_ParseTuple(args, "OOOOddOO:solve", &q_obj, &target_obj, &fingers_obj,
                          &iterations_obj, &refine_m, &d_min_m, &stall_obj, &history) ||
        get_int(iterations_obj, &max_iterations, 0, INT_MAX - 1, "max_iterations") < 0 ||
        get_int(stall_obj, &stall, 1, INT_MAX, "stall") < 0)
        return NULL;
    Py_buffer b[3]; /* fingers, q, target */
    int nf;
    if (take_finger_buffers(self, q_obj, 1, fingers_obj, target_obj, 0, "target", b, &nf) < 0)
        return NULL;
    PyObject *result = NULL;
    Work w;
    if (nf < 1) {
        PyErr_SetString(PyExc_ValueError, "fingers must not be empty");
    } else if (work_init(&w, self, b[0].buf, nf, b[2].buf, max_iterations) == 0) {
        Outcome out;
        int status;
        double *q = b[1].buf;
        if (history == Py_None) {
            /* No Python call inside: other threads (threaded executors' workers) run meanwhile. */
            Py_BEGIN_ALLOW_THREADS
            status = lm_loop(&w, q, max_iterations, refine_m, d_min_m, stall, NULL, &out);
            Py_END_ALLOW_THREADS
        } else {
            status = lm_loop(&w, q, max_iterations, refine_m, d_min_m, stall, history, &out);
        }
        if (status == 0) result = Py_BuildValue("iid", out.outcome, out.iterations, out.error);
        work_free(&w);
    }
    release_buffers(b, 3);
    return result;
}

/* stack(q, fingers, stack_out, jacobian_out or None): the contact stack and its Jacobian. */
static PyObject *Tree_stack(Tree *self, PyObject *args) {
    PyObject *q_obj, *fingers_obj, *stack_obj, *jac_obj;
    if (!PyArg_ParseTuple(args, "OOOO:stack", &q_obj, &fingers_obj, &stack_obj, &jac_obj))
        return NULL;
    Py_buffer b[4];
    int nf, held = 3, ok = 0, jac = jac_obj != Py_None;
    if (take_finger_buffers(self, q_obj, 0, fingers_obj, stack_obj, 1, "stack_out", b, &nf) < 0)
        return NULL;
    if (jac) {
        if (get_items(jac_obj, &b[3], (Py_ssize_t)6 * nf * self->nv, 0, 1, "jacobian_out") < 0) {
            release_buffers(b, held);
            return NULL;
        }
        held = 4;
    }
    Work w;
    if (work_init(&w, self, b[0].buf, nf, b[2].buf, 0) == 0) {
        forward(self, b[1].buf, w.M);
        stack_of(self, w.M, b[0].buf, nf, b[2].buf);
        if (jac) jacobian_of(self, w.M, b[0].buf, nf, b[2].buf, b[3].buf);
        work_free(&w);
        ok = 1;
    }
    release_buffers(b, held);
    if (!ok) return NULL;
    Py_RETURN_NONE;
}

/* errors(q, target, fingers, out): per finger, the distance [m] of its contact point from the
 * target's (out[:nf]) and of its sphere centre from the target's (out[nf:]). */
static PyObject *Tree_errors(Tree *self, PyObject *args) {
    PyObject *q_obj, *target_obj, *fingers_obj, *out_obj;
    if (!PyArg_ParseTuple(args, "OOOO:errors", &q_obj, &target_obj, &fingers_obj, &out_obj))
        return NULL;
    Py_buffer b[4];
    int nf, ok = 0;
    if (take_finger_buffers(self, q_obj, 0, fingers_obj, target_obj, 0, "target", b, &nf) < 0)
        return NULL;
    if (get_items(out_obj, &b[3], 2 * (Py_ssize_t)nf, 0, 1, "out") < 0) {
        release_buffers(b, 3);
        return NULL;
    }
    double *stack = PyMem_Malloc(6 * (size_t)nf * sizeof(double) + 1);
    if (stack == NULL) {
        PyErr_NoMemory();
    } else if (stack_at(self, b[1].buf, b[0].buf, nf, stack) == 0) {
        const double *target = b[2].buf;
        double *out = b[3].buf;
        for (int k = 0; k < 2 * nf; k++) {  /* stack: (p, r) per finger */
            const double *a = stack + 3 * k, *t = target + 3 * k;
            double d[3] = {a[0] - t[0], a[1] - t[1], a[2] - t[2]};
            out[k % 2 == 0 ? k / 2 : nf + k / 2] = sqrt(dot(d, d, 3));
        }
        ok = 1;
    }
    PyMem_Free(stack);
    release_buffers(b, 4);
    if (!ok) return NULL;
    Py_RETURN_NONE;
}

/* integrate(q, v, out, clamp): q (+) v, the joints clamped to their limits if clamp. */
static PyObject *Tree_integrate(Tree *self, PyObject *args) {
    PyObject *q_obj, *v_obj, *out_obj;
    int clamp;
    if (!PyArg_ParseTuple(args, "OOOp:integrate", &q_obj, &v_obj, &out_obj, &clamp)) return NULL;
    if (check_ready(self) < 0) return NULL;
    Py_buffer qb, vb, ob;
    if (get_items(q_obj, &qb, self->nq, 0, 0, "q") < 0) return NULL;
    if (get_items(v_obj, &vb, self->nv, 0, 0, "v") < 0) {
        PyBuffer_Release(&qb);
        return NULL;
    }
    if (get_items(out_obj, &ob, self->nq, 0, 1, "out") < 0) {
        PyBuffer_Release(&vb);
        PyBuffer_Release(&qb);
        return NULL;
    }
    integrate_clamped(self, qb.buf, vb.buf, ob.buf, clamp);
    PyBuffer_Release(&ob);
    PyBuffer_Release(&vb);
    PyBuffer_Release(&qb);
    Py_RETURN_NONE;
}

/* ------------------------------------------------------------------ collision repair -- */

/* Adds to `row` (nv) `sign` times n^T J(x), J(x) the Jacobian with respect to v of the point x
 * (world frame) fixed to tree joint k (-1: the world, which does not move). */
static void add_point_row(const Tree *T, const Pose *M, int k, const double *x, const double *n,
                          double sign, double *row) {
    if (k < 0) return;
    for (int c = 0; c < 3; c++) {
        double col[3], m[3];
        wrist_columns(&M[0], x, c, col, m);
        row[c] += sign * (n[0] * col[0] + n[1] * col[1] + n[2] * col[2]);
        row[3 + c] += sign * (n[0] * m[0] + n[1] * m[1] + n[2] * m[2]);
    }
    for (int j = k; j > 0; j = T->parent[j]) {
        double m[3];
        joint_velocity(T, M, j, x, m);
        row[T->v_index[j]] += sign * T->scale[j] * (n[0] * m[0] + n[1] * m[1] + n[2] * m[2]);
    }
}

/* One step of sahgrasp/ik/solver.py's `_separate`: the contact rows of `fingers` (towards
 * `target`) and one row per penetrating pair (body b away from body a along the normal by the
 * depth) solved together in damped least squares (damping 1e-6, bounds as an active set), the
 * joints clamped. `joints` holds per pair the tree joints of a and b (-1: the world), `points`
 * their witnesses. Writes the new configuration to `out`; returns 0 if the rows are degenerate,
 * -1 if out of memory. */
static int repair_step(const Tree *T, const double *q, const double *target,
                       const long long *fingers, int nf, const long long *joints,
                       const double *points, const double *normals, const double *depths, int np,
                       double *out) {
    int nv = T->nv, m = 6 * nf, rows = m + np;
    Pose *M = PyMem_Malloc((size_t)T->nj * sizeof(Pose));
    double *buf =
        PyMem_Malloc(((size_t)rows * (nv + 2) + (size_t)nv * (2 * nv + 3)) * sizeof(double));
    int *free_cols = PyMem_Malloc((size_t)nv * sizeof(int));
    if (!M || !buf || !free_cols) {
        PyMem_Free(M), PyMem_Free(buf), PyMem_Free(free_cols);
        return -1;
    }
    double *J = buf, *e = J + (size_t)rows * nv, *stack = e + rows, *g = stack + m;
    double *A = g + nv, *L = A + (size_t)nv * nv, *x = L + (size_t)nv * nv, *step = x + nv;
    forward(T, q, M);
    stack_of(T, M, fingers, nf, stack);
    jacobian_of(T, M, fingers, nf, stack, J);
    for (int i = 0; i < m; i++) e[i] = target[i] - stack[i];
    memset(J + (size_t)m * nv, 0, (size_t)np * nv * sizeof(double));
    for (int p = 0; p < np; p++) {
        double *row = J + (size_t)(m + p) * nv;
        add_point_row(T, M, (int)joints[2 * p + 1], points + 6 * p + 3, normals + 3 * p, 1.0, row);
        add_point_row(T, M, (int)joints[2 * p], points + 6 * p, normals + 3 * p, -1.0, row);
        e[m + p] = depths[p];
    }
    for (int c = 0; c < nv; c++) g[c] = 0.0;
    for (int i = 0; i < rows; i++)
        for (int c = 0; c < nv; c++) g[c] += J[(size_t)i * nv + c] * e[i];
    int n = 0;
    for (int c = 0; c < nv; c++)
        if (!fixed_at_bound(T, q, c, g[c])) free_cols[n++] = c;
    for (int a = 0; a < n; a++) {
        for (int b = 0; b <= a; b++) {
            double sum = 0.0;
            for (int i = 0; i < rows; i++)
                sum += J[(size_t)i * nv + free_cols[a]] * J[(size_t)i * nv + free_cols[b]];
            A[a * n + b] = sum;
        }
        g[a] = g[free_cols[a]]; /* free_cols ascend: in place */
    }
    int ok = damped_solve(A, g, 1e-6, n, L, x);
    if (ok) {
        memset(step, 0, (size_t)nv * sizeof(double));
        for (int a = 0; a < n; a++) step[free_cols[a]] = x[a];
        integrate_clamped(T, q, step, out, 1);
    }
    PyMem_Free(M), PyMem_Free(buf), PyMem_Free(free_cols);
    return ok;
}

/* repair(q, target, fingers, joints, points, normals, depths, out) -> bool (see repair_step). */
static PyObject *Tree_repair(Tree *self, PyObject *args) {
    enum { Q, TARGET, FINGERS, JOINTS, POINTS, NORMALS, DEPTHS, OUT, N_ARGS };
    PyObject *o[N_ARGS];
    if (!PyArg_ParseTuple(args, "OOOOOOOO:repair", &o[Q], &o[TARGET], &o[FINGERS], &o[JOINTS],
                          &o[POINTS], &o[NORMALS], &o[DEPTHS], &o[OUT]))
        return NULL;
    if (check_ready(self) < 0) return NULL;
    static const char *names[N_ARGS] = {"q", "target", "fingers", "joints", "points", "normals",
                                        "depths", "out"};
    static const char *formats[N_ARGS] = {"d", "d", "q", "q", "d", "d", "d", "d"};
    /* The sizes follow from the fingers' and depths' lengths, so those two are taken first. */
    static const int order[N_ARGS] = {FINGERS, DEPTHS, Q, TARGET, JOINTS, POINTS, NORMALS, OUT};
    Py_buffer b[N_ARGS];
    int held = 0, status = -2, nf = 0, np = 0;
    for (; held < N_ARGS; held++) {
        int i = order[held];
        Py_ssize_t sizes[N_ARGS] = {self->nq, 6 * nf, -1, 2 * np, 6 * np, 3 * np, -1, self->nq};
        if (get_items(o[i], &b[i], sizes[i], formats[i][0] == 'q', i == OUT, names[i]) < 0) break;
        if (i == FINGERS) nf = (int)(b[i].len / 8);
        if (i == DEPTHS) np = (int)(b[i].len / 8);
    }
    if (held == N_ARGS) {
        const long long *f = b[FINGERS].buf, *j = b[JOINTS].buf;
        int bad = nf < 1;
        if (bad) PyErr_SetString(PyExc_ValueError, "repair: fingers must not be empty");
        for (int k = 0; k < nf && !bad; k++)
            if ((bad = f[k] < 0 || f[k] >= self->nf))
                PyErr_Format(PyExc_ValueError, "repair: fingers[%d] = %lld: finger index out of "
                             "range 0 to %d", k, f[k], self->nf - 1);
        for (int k = 0; k < 2 * np && !bad; k++)
            if ((bad = j[k] < FIXED_JOINT || j[k] >= self->nj))
                PyErr_Format(PyExc_ValueError, "repair: joints: joint out of range: %lld (valid: "
                             "-1, the fixed world, to %d)", j[k], self->nj - 1);
        if (!bad) {
            status = repair_step(self, b[Q].buf, b[TARGET].buf, f, nf, j, b[POINTS].buf,
                                 b[NORMALS].buf, b[DEPTHS].buf, np, b[OUT].buf);
            if (status < 0) PyErr_NoMemory();
        }
    }
    for (int k = 0; k < held; k++) PyBuffer_Release(&b[order[k]]);
    if (status < 0) return NULL;
    return PyBool_FromLong(status);
}

/* ------------------------------------------------------------------ self-collision -- */

/* set_shapes(joints, placements, kinds, sizes, balls, pairs): the hand's collision shapes
 * (tree joint, placement in it as 12 values, kind of _gjk.h up to the ellipsoid, 4 sizes: box
 * half extents, cylinder radius and half length or ellipsoid radii, then the inflation), their
 * bounding balls (local centre, radius) and the pairs to check. */
static PyObject *Tree_set_shapes(Tree *self, PyObject *args, PyObject *kwds) {
    enum { JOINTS, PLACEMENTS, KINDS, SIZES, BALLS, PAIRS, N_ARGS };
    static char *kwlist[] = {"joints", "placements", "kinds", "sizes", "balls", "pairs", NULL};
    PyObject *o[N_ARGS];
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "|$OOOOOO:set_shapes", kwlist, &o[0], &o[1],
                                     &o[2], &o[3], &o[4], &o[5]) ||
        missing_keyword("set_shapes", kwlist, kwds) < 0)
        return NULL;
    if (check_ready(self) < 0) return NULL;
    static const char *names[N_ARGS] = {"joints", "placements", "kinds", "sizes", "balls", "pairs"};
    static const char *formats[N_ARGS] = {"q", "d", "q", "d", "d", "q"};
    Py_buffer b[N_ARGS];
    int held = 0, ns = 0, ok = 0;
    for (; held < N_ARGS; held++) {
        Py_ssize_t sizes[N_ARGS] = {-1, 12 * ns, ns, 4 * ns, 4 * ns, -1};
        if (get_items(o[held], &b[held], sizes[held], formats[held][0] == 'q', 0, names[held]) < 0)
            break;
        if (held == JOINTS) ns = (int)(b[0].len / 8);
    }
    if (held == N_ARGS) {
        const long long *joints = b[JOINTS].buf, *kinds = b[KINDS].buf, *pairs = b[PAIRS].buf;
        int npairs = (int)(b[PAIRS].len / 16), bad = 0;
        if (b[PAIRS].len % 16 != 0) {
            bad = 1;
            PyErr_Format(PyExc_ValueError, "set_shapes: pairs: expected an even number of "
                         "values (pairs of shapes), got %zd", b[PAIRS].len / 8);
        }
        for (int k = 0; k < ns && !bad; k++) {
            bad = 1;
            if (joints[k] < 0 || joints[k] >= self->nj)
                PyErr_Format(PyExc_ValueError, "set_shapes: joints[%d] = %lld: expected a joint "
                             "of the tree, 0 to %d", k, joints[k], self->nj - 1);
            else if (kinds[k] < SHAPE_POINT || kinds[k] > SHAPE_ELLIPSOID)
                PyErr_Format(PyExc_ValueError, "set_shapes: kinds[%d] = %lld: expected "
                             "SHAPE_POINT to SHAPE_ELLIPSOID, %d to %d", k, kinds[k],
                             SHAPE_POINT, SHAPE_ELLIPSOID);
            else
                bad = 0;
        }
        for (int k = 0; k < 2 * npairs && !bad; k++)
            if (pairs[k] < 0 || pairs[k] >= ns) {
                bad = 1;
                PyErr_Format(PyExc_ValueError, "set_shapes: pairs: shape %lld of pair %d is not "
                             "one of the %d shapes", pairs[k], k / 2, ns);
            }
        int *joint = PyMem_Malloc((size_t)ns * sizeof(int) + 1),
            *pair = PyMem_Malloc(2 * (size_t)npairs * sizeof(int) + 1);
        Pose *place = PyMem_Malloc((size_t)ns * sizeof(Pose) + 1);
        GjkShape *shapes = PyMem_Calloc((size_t)ns + 1, sizeof(GjkShape));
        double *ball = PyMem_Malloc(4 * (size_t)ns * sizeof(double) + 1);
        if (bad) {
            /* the error is set */
        } else if (!joint || !pair || !place || !shapes || !ball) {
            PyErr_NoMemory();
        } else {
            const double *placements = b[PLACEMENTS].buf, *sizes = b[SIZES].buf;
            for (int k = 0; k < ns; k++) {
                joint[k] = (int)joints[k];
                memcpy(place[k].R, placements + 12 * k, 9 * sizeof(double));
                memcpy(place[k].t, placements + 12 * k + 9, 3 * sizeof(double));
                shapes[k].kind = (int)kinds[k];
                memcpy(shapes[k].size, sizes + 4 * k, 3 * sizeof(double));
                shapes[k].radius = sizes[4 * k + 3];
            }
            for (int k = 0; k < 2 * npairs; k++) pair[k] = (int)pairs[k];
            memcpy(ball, b[BALLS].buf, 4 * (size_t)ns * sizeof(double));
            PyMem_Free(self->shape_joint), PyMem_Free(self->shape_place), PyMem_Free(self->shapes);
            PyMem_Free(self->ball), PyMem_Free(self->pairs);
            self->shape_joint = joint, self->shape_place = place, self->shapes = shapes;
            self->ball = ball, self->pairs = pair, self->ns = ns, self->npairs = npairs;
            joint = NULL, pair = NULL, place = NULL, shapes = NULL, ball = NULL;
            ok = 1;
        }
        PyMem_Free(joint), PyMem_Free(pair), PyMem_Free(place), PyMem_Free(shapes);
        PyMem_Free(ball);
    }
    release_buffers(b, held);
    if (!ok) return NULL;
    Py_RETURN_NONE;
}

/* The pairs whose shapes come within `margin_m` at q, into `found` (up to `most` of them, in
 * pair order): how many; -1 if out of memory. */
static int pairs_within(const Tree *T, const double *q, double margin_m, long long *found,
                        int most) {
    Pose *M = PyMem_Malloc((size_t)T->nj * sizeof(Pose));
    GjkShape *shapes = PyMem_Malloc((size_t)T->ns * sizeof(GjkShape) + 1);
    double *centres = PyMem_Malloc(3 * (size_t)T->ns * sizeof(double) + 1);
    int count = -1;
    if (M && shapes && centres) {
        forward(T, q, M);
        for (int k = 0; k < T->ns; k++) {
            Pose world;
            compose(&M[T->shape_joint[k]], &T->shape_place[k], &world);
            shapes[k] = T->shapes[k];
            memcpy(shapes[k].R, world.R, sizeof world.R);
            memcpy(shapes[k].t, world.t, sizeof world.t);
            const double *c = T->ball + 4 * k;
            for (int i = 0; i < 3; i++)
                centres[3 * k + i] = world.R[3 * i] * c[0] + world.R[3 * i + 1] * c[1] +
                                     world.R[3 * i + 2] * c[2] + world.t[i];
        }
        count = 0;
        for (int p = 0; p < T->npairs && count < most; p++) {
            int a = T->pairs[2 * p], b = T->pairs[2 * p + 1];
            double gap[3], reach = T->ball[4 * a + 3] + T->ball[4 * b + 3] + margin_m;
            for (int i = 0; i < 3; i++) gap[i] = centres[3 * a + i] - centres[3 * b + i];
            if (dot(gap, gap, 3) >= reach * reach) continue;  /* the bounding balls are apart */
            if (gjk_within(&shapes[a], &shapes[b], margin_m)) found[count++] = p;
        }
    }
    PyMem_Free(M), PyMem_Free(shapes), PyMem_Free(centres);
    return count;
}

/* pairs_within(q, margin_m, out) -> int: the checked pairs closer than margin_m >= 0 [m] at q
 * (intersecting if 0), their indices into out (the first len(out)); how many were written. */
static PyObject *Tree_pairs_within(Tree *self, PyObject *args) {
    PyObject *q_obj, *out_obj;
    double margin_m;
    if (!PyArg_ParseTuple(args, "OdO:pairs_within", &q_obj, &margin_m, &out_obj)) return NULL;
    if (check_ready(self) < 0) return NULL;
    if (!(margin_m >= 0.0)) {
        PyErr_SetString(PyExc_ValueError, "pairs_within: margin_m must be >= 0");
        return NULL;
    }
    Py_buffer qb, ob;
    if (get_items(q_obj, &qb, self->nq, 0, 0, "q") < 0) return NULL;
    if (get_items(out_obj, &ob, -1, 1, 1, "out") < 0) {
        PyBuffer_Release(&qb);
        return NULL;
    }
    int count = pairs_within(self, qb.buf, margin_m, ob.buf, (int)(ob.len / 8));
    PyBuffer_Release(&ob);
    PyBuffer_Release(&qb);
    if (count < 0) return PyErr_NoMemory();
    return PyLong_FromLong(count);
}

/* --------------------------------------------------------------- hand-object checks -- */

/* An object's convex pieces in its own frame, with a coarse level of cells (balls holding
 * groups of pieces), for the compiled hand-object verdicts (sahgrasp/objects/clearance.py). */
typedef struct {
    PyObject_HEAD
    int n, ncells;
    GjkShape *shapes;    /* placed in the object frame; convex ones point into the arrays below */
    double *ball;        /* per piece: centre (object frame), radius */
    double *vertices;    /* every convex piece's local vertices */
    int *first;          /* per vertex of every piece, where its neighbours start (count + 1 per
                            piece with neighbours) */
    int *neighbours;
    int *starts;         /* per piece with neighbours, GJK_DIRECTIONS start vertices */
    double *cell_ball;   /* per cell: centre, radius */
    int *cell_start;     /* ncells + 1 offsets into cell_members */
    int *cell_members;
} Pieces;

/* Free the arrays and leave the object uninitialised (shapes NULL). */
static void pieces_clear(Pieces *self) {
    void **arrays[] = {(void **)&self->shapes,     (void **)&self->ball,
                       (void **)&self->vertices,   (void **)&self->first,
                       (void **)&self->neighbours, (void **)&self->starts,
                       (void **)&self->cell_ball,  (void **)&self->cell_start,
                       (void **)&self->cell_members};
    for (size_t k = 0; k < sizeof arrays / sizeof arrays[0]; k++) {
        PyMem_Free(*arrays[k]);
        *arrays[k] = NULL;
    }
}

static void Pieces_dealloc(Pieces *self) {
    pieces_clear(self);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

/* Pieces(kinds, placements, sizes, balls, vertex_start, vertices, first, neighbours,
 *        cell_balls, cell_start, cell_members): per piece its kind (_gjk.h), placement (12
 * values), sizes (3) and inflation (1) as `sizes` (4 per piece), bounding ball (4); convex
 * pieces' vertices (piece p: rows vertex_start[p] to vertex_start[p + 1]), and for each vertex
 * the offsets `first` (one more than the vertices of a piece with neighbours, per such piece
 * laid out in piece order; -1 as its first value for a piece without) into `neighbours`. */
static int Pieces_init(Pieces *self, PyObject *args, PyObject *kwds) {
    enum { KINDS, PLACEMENTS, SIZES, BALLS, VSTART, VERTICES, FIRST, NEIGHBOURS, CBALLS, CSTART,
           CMEMBERS, N_ARGS };
    static char *kwlist[] = {"kinds", "placements", "sizes", "balls", "vertex_start", "vertices",
                             "first", "neighbours", "cell_balls", "cell_start", "cell_members",
                             NULL};
    PyObject *o[N_ARGS];
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "|$OOOOOOOOOOO", kwlist, &o[0], &o[1], &o[2],
                                     &o[3], &o[4], &o[5], &o[6], &o[7], &o[8], &o[9], &o[10]) ||
        missing_keyword("Pieces", kwlist, kwds) < 0)
        return -1;
    if (self->shapes != NULL) {
        PyErr_SetString(PyExc_RuntimeError, "Pieces is already initialised");
        return -1;
    }
    static const char *formats[N_ARGS] = {"q", "d", "d", "d", "q", "d", "q", "q", "d", "q", "q"};
    static const char *names[N_ARGS] = {"kinds", "placements", "sizes", "balls", "vertex_start",
                                        "vertices", "first", "neighbours", "cell_balls",
                                        "cell_start", "cell_members"};
    Py_buffer b[N_ARGS];
    int held = 0, status = -1, n = 0, ncells = 0;
    for (; held < N_ARGS; held++) {
        Py_ssize_t sizes[N_ARGS] = {-1, 12 * n, 4 * n, 4 * n, n + 1, -1, -1, -1, -1, -1, n};
        if (get_items(o[held], &b[held], sizes[held], formats[held][0] == 'q', 0, names[held]) < 0)
            goto out;
        if (held == KINDS) n = (int)(b[KINDS].len / 8);
        if (held == CBALLS) ncells = (int)(b[CBALLS].len / 32);
    }
    const long long *kinds = b[KINDS].buf, *vstart = b[VSTART].buf, *first = b[FIRST].buf,
                    *nb = b[NEIGHBOURS].buf, *cstart = b[CSTART].buf, *members = b[CMEMBERS].buf;
    Py_ssize_t nvert = b[VERTICES].len / 24, nfirst = b[FIRST].len / 8, nnb = b[NEIGHBOURS].len / 8;
    /* The first array at fault and what it must be. */
    const char *fault = NULL, *valid = NULL;
    if (b[VERTICES].len % 24 != 0)
        fault = "vertices", valid = "rows of 3 coordinates";
    else if (b[CBALLS].len % 32 != 0)
        fault = "cell_balls", valid = "rows of 4 values (centre, radius)";
    else if (b[CSTART].len != 8 * (Py_ssize_t)(ncells + 1) || cstart[0] != 0 || cstart[ncells] != n)
        fault = "cell_start", valid = "one offset per cell and one more, from 0 to the pieces";
    else if (vstart[0] != 0 || vstart[n] != nvert)
        fault = "vertex_start", valid = "offsets from 0 to the vertices";
    for (int p = 0; p < n && !fault; p++)
        if (kinds[p] < SHAPE_POINT || kinds[p] > SHAPE_CONVEX)
            fault = "kinds", valid = "SHAPE_POINT to SHAPE_CONVEX";
        else if (vstart[p + 1] < vstart[p] ||
                 (kinds[p] == SHAPE_CONVEX) != (vstart[p + 1] > vstart[p]))
            fault = "vertex_start", valid = "ascending offsets, vertices for convex pieces only";
    for (int k = 0; k < ncells && !fault; k++)
        if (cstart[k + 1] < cstart[k]) fault = "cell_start", valid = "ascending offsets";
    for (int k = 0; k < n && !fault; k++)
        if (members[k] < 0 || members[k] >= n) fault = "cell_members", valid = "piece indices";
    for (Py_ssize_t e = 0; e < nnb && !fault; e++)
        if (nb[e] < 0) fault = "neighbours", valid = "vertex indices >= 0";
    if (fault != NULL) {
        PyErr_Format(PyExc_ValueError, "Pieces: %s: expected %s", fault, valid);
        goto out;
    }
    int bad = 0;
    self->shapes = PyMem_Calloc((size_t)n + 1, sizeof(GjkShape));
    self->ball = PyMem_Malloc(4 * (size_t)n * sizeof(double) + 1);
    self->vertices = PyMem_Malloc(3 * (size_t)nvert * sizeof(double) + 1);
    self->first = PyMem_Malloc((size_t)nfirst * sizeof(int) + 1);
    self->neighbours = PyMem_Malloc((size_t)nnb * sizeof(int) + 1);
    self->cell_ball = PyMem_Malloc(4 * (size_t)ncells * sizeof(double) + 1);
    self->cell_start = PyMem_Malloc(((size_t)ncells + 1) * sizeof(int));
    self->cell_members = PyMem_Malloc((size_t)n * sizeof(int) + 1);
    self->starts = PyMem_Malloc((size_t)n * GJK_DIRECTIONS * sizeof(int) + 1);
    if (!self->shapes || !self->ball || !self->vertices || !self->first || !self->neighbours ||
        !self->cell_ball || !self->cell_start || !self->cell_members || !self->starts) {
        PyErr_NoMemory();
        goto out;
    }
    memcpy(self->ball, b[BALLS].buf, 4 * (size_t)n * sizeof(double));
    memcpy(self->vertices, b[VERTICES].buf, 3 * (size_t)nvert * sizeof(double));
    memcpy(self->cell_ball, b[CBALLS].buf, 4 * (size_t)ncells * sizeof(double));
    for (Py_ssize_t e = 0; e < nfirst; e++) self->first[e] = (int)first[e];
    for (Py_ssize_t e = 0; e < nnb; e++) self->neighbours[e] = (int)nb[e];
    for (int k = 0; k <= ncells; k++) self->cell_start[k] = (int)cstart[k];
    for (int k = 0; k < n; k++) self->cell_members[k] = (int)members[k];
    const double *placements = b[PLACEMENTS].buf, *sizes = b[SIZES].buf;
    Py_ssize_t at = 0; /* the next piece's offsets in `first` */
    for (int p = 0; p < n; p++) {
        GjkShape *g = &self->shapes[p];
        g->kind = (int)kinds[p];
        memcpy(g->R, placements + 12 * p, 9 * sizeof(double));
        memcpy(g->t, placements + 12 * p + 9, 3 * sizeof(double));
        memcpy(g->size, sizes + 4 * p, 3 * sizeof(double));
        g->radius = sizes[4 * p + 3];
        if (g->kind != SHAPE_CONVEX) continue;
        g->vertices = self->vertices + 3 * vstart[p];
        g->count = (int)(vstart[p + 1] - vstart[p]);
        for (int i = 0; i < 3; i++) {  /* the box of its vertices, for the separating axes */
            double low = INFINITY, high = -INFINITY;
            for (int v = 0; v < g->count; v++) {
                low = fmin(low, g->vertices[3 * v + i]);
                high = fmax(high, g->vertices[3 * v + i]);
            }
            g->centre[i] = 0.5 * (low + high);
            g->size[i] = 0.5 * (high - low);
        }
        if (at >= nfirst) bad = 1;
        else if (first[at] < 0) at++; /* no neighbours: a scan of the vertices */
        else if (at + g->count + 1 > nfirst) bad = 1;
        else {
            g->first = self->first + at;
            g->neighbours = self->neighbours;
            int *starts = self->starts + (size_t)p * GJK_DIRECTIONS;
            for (int k = 0; k < GJK_DIRECTIONS; k++) {
                double high = -INFINITY, l[3];
                gjk_cell_direction(k, l);
                for (int v = 0; v < g->count; v++) {
                    double h = gjk_dot(g->vertices + 3 * v, l);
                    if (h > high) high = h, starts[k] = v;
                }
            }
            g->starts = starts;
            for (int v = 0; v < g->count && !bad; v++)
                bad = g->first[v] > g->first[v + 1] || g->first[v + 1] > nnb;
            for (int e = g->first[0]; e < g->first[g->count] && !bad; e++)
                bad = self->neighbours[e] >= g->count;
            at += g->count + 1;
        }
    }
    if (bad || at != nfirst) {
        PyErr_SetString(PyExc_ValueError, "Pieces: first, neighbours: expected per convex piece "
                        "with neighbours its vertices' offsets into neighbours and one more, "
                        "each neighbour a vertex of that piece, per piece without -1");
        goto out;
    }
    self->n = n;
    self->ncells = ncells;
    status = 0;
out:
    if (status < 0) pieces_clear(self); /* a failed init leaves an uninitialised object */
    release_buffers(b, held);
    return status;
}

static PyTypeObject PiecesType = {
    PyVarObject_HEAD_INIT(NULL, 0).tp_name = "sahgrasp.ik._lm.Pieces",
    .tp_basicsize = sizeof(Pieces),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "An object's convex pieces and their coarse cells, for the hand-object verdicts.",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)Pieces_init,
    .tp_dealloc = (destructor)Pieces_dealloc,
};

static double ball_gap(const double *a, const double *b) {
    double d[3] = {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
    return sqrt(dot(d, d, 3)) - a[3] - b[3];
}

/* The smallest signed distance [m] from the shape (placed in the object frame, its bounding
 * ball `ball`) to the pieces if it is below `limit_m`, else some value >= limit_m; -inf when
 * the cores intersect (a penetration of at least the inflations). Returns at the first value
 * below `stop_m`. `gaps`: room for one value per cell. */
static double shape_to_pieces(const Pieces *P, const GjkShape *shape, const double *ball,
                              double limit_m, double stop_m, double *gaps) {
    double best = limit_m;
    for (int k = 0; k < P->ncells; k++) gaps[k] = ball_gap(ball, P->cell_ball + 4 * k);
    for (;;) {  /* the nearest cell not yet searched whose ball comes below the best so far */
        int k = -1;
        for (int c = 0, low = 0; c < P->ncells; c++)
            if (gaps[c] < best && (!low || gaps[c] < gaps[k])) k = c, low = 1;
        if (k < 0) return best;
        gaps[k] = INFINITY;
        for (int m = P->cell_start[k]; m < P->cell_start[k + 1]; m++) {
            int p = P->cell_members[m];
            if (ball_gap(ball, P->ball + 4 * p) >= best) continue;
            const GjkShape *piece = &P->shapes[p];
            if (gjk_box_gap(shape, piece) >= best) continue;
            double inflation = shape->radius + piece->radius;
            double core = gjk_core_distance(shape, piece, best + inflation);
            double d = core <= 0.0 ? -INFINITY : core - inflation;
            if (d < best) best = d;
            if (best < stop_m) return best;
        }
    }
}

/* The hand's shapes at q placed in the frame of an object at T_world_object (12 values), and
 * their bounding balls there (4 values each); 0, or -1 out of memory. */
static int shapes_in_object(const Tree *T, const double *q, const double *T_world_object,
                            GjkShape *shapes, double *balls) {
    Pose *M = PyMem_Malloc((size_t)T->nj * sizeof(Pose)), object, inverse;
    if (M == NULL) return -1;
    forward(T, q, M);
    memcpy(object.R, T_world_object, 9 * sizeof(double));
    memcpy(object.t, T_world_object + 9, 3 * sizeof(double));
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++) inverse.R[3 * i + j] = object.R[3 * j + i];
        inverse.t[i] = -(object.R[i] * object.t[0] + object.R[3 + i] * object.t[1] +
                         object.R[6 + i] * object.t[2]);
    }
    for (int k = 0; k < T->ns; k++) {
        Pose world, local;
        compose(&M[T->shape_joint[k]], &T->shape_place[k], &world);
        compose(&inverse, &world, &local);
        shapes[k] = T->shapes[k];
        memcpy(shapes[k].R, local.R, sizeof local.R);
        memcpy(shapes[k].t, local.t, sizeof local.t);
        const double *c = T->ball + 4 * k;
        for (int i = 0; i < 3; i++)
            balls[4 * k + i] = local.R[3 * i] * c[0] + local.R[3 * i + 1] * c[1] +
                               local.R[3 * i + 2] * c[2] + local.t[i];
        balls[4 * k + 3] = c[3];
    }
    PyMem_Free(M);
    return 0;
}

/* The buffers of an object query: q, T_world_object (4 x 4), per-shape thresholds; 0 or -1. */
static int take_object_buffers(const Tree *self, PyObject *pieces, PyObject *q_obj,
                               PyObject *T_obj, PyObject *th_obj, Py_buffer b[3]) {
    if (check_ready(self) < 0) return -1;
    if (!PyObject_TypeCheck(pieces, &PiecesType) || ((Pieces *)pieces)->shapes == NULL) {
        PyErr_SetString(PyExc_TypeError, "pieces must be an initialised Pieces");
        return -1;
    }
    if (!self->ns) {
        PyErr_SetString(PyExc_ValueError, "the tree has no collision shapes (set_shapes)");
        return -1;
    }
    if (get_items(q_obj, &b[0], self->nq, 0, 0, "q") < 0) return -1;
    if (get_items(T_obj, &b[1], 16, 0, 0, "T_world_object") < 0) {
        release_buffers(b, 1);
        return -1;
    }
    if (get_items(th_obj, &b[2], self->ns, 0, 0, "thresholds") < 0) {
        release_buffers(b, 2);
        return -1;
    }
    return 0;
}

/* The 4 x 4 row-major placement as the 12 values of a Pose. */
static void pose_values(const double *T, double *out) {
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++) out[3 * i + j] = T[4 * i + j];
        out[9 + i] = T[4 * i + 3];
    }
}

/* A smallest lower bound [m] of the shape's distance to any cell (its ball's gap to theirs). */
static double gap_to_cells(const Pieces *P, const double *ball) {
    double gap = INFINITY;
    for (int k = 0; k < P->ncells; k++) gap = fmin(gap, ball_gap(ball, P->cell_ball + 4 * k));
    return gap;
}

/* The verdict and clearance of object_clearance (below) on shapes placed in the object frame. */
static void clearance_of(const Pieces *P, GjkShape *shapes, const double *balls, int ns,
                         const double *thresholds, int *order, double *bounds, double *gaps,
                         int *inside, double *best, int *closest) {
    *inside = 0, *best = INFINITY, *closest = -1;
    for (int k = 0; k < ns && !*inside; k++) {  /* the excepted tips first: few */
        if (thresholds[k] >= 0.0) continue;
        double d = shape_to_pieces(P, &shapes[k], balls + 4 * k, thresholds[k], thresholds[k],
                                   gaps);
        *inside = d < thresholds[k];
    }
    /* The other shapes nearest first (by their balls), so that the smallest distance found so
     * far soon rules out the far ones without a GJK call. */
    int n = 0;
    for (int k = 0; k < ns; k++) {
        if (thresholds[k] < 0.0) continue;
        double gap = gap_to_cells(P, balls + 4 * k);
        int at = n++;
        for (; at > 0 && bounds[at - 1] > gap; at--)
            bounds[at] = bounds[at - 1], order[at] = order[at - 1];
        bounds[at] = gap, order[at] = k;
    }
    for (int i = 0; i < n && !*inside && bounds[i] < *best; i++) {
        int k = order[i];
        double d = shape_to_pieces(P, &shapes[k], balls + 4 * k, *best, thresholds[k], gaps);
        *inside = d < thresholds[k];
        if (d < *best) *best = d, *closest = k;
    }
}

/* The hand's shapes of one object query, placed in the object frame, and the query's scratch. */
typedef struct {
    GjkShape *shapes;
    double *balls;   /* bounding ball per shape, object frame: centre, radius */
    double *gaps;    /* per cell */
    double *bounds;  /* per shape */
    int *order;      /* per shape */
} ObjectQuery;

static void object_query_free(ObjectQuery *Q) {
    PyMem_Free(Q->shapes), PyMem_Free(Q->balls), PyMem_Free(Q->gaps), PyMem_Free(Q->bounds);
    PyMem_Free(Q->order);
}

/* Q for the tree at q and an object at the 4 x 4 row-major T_world_object: 0, or -1 with
 * MemoryError and nothing held. */
static int object_query_init(const Tree *T, const Pieces *P, const double *q,
                             const double *T_world_object, ObjectQuery *Q) {
    int ns = T->ns;
    double placement[12];
    Q->shapes = PyMem_Malloc((size_t)ns * sizeof(GjkShape));
    Q->balls = PyMem_Malloc(4 * (size_t)ns * sizeof(double));
    Q->gaps = PyMem_Malloc(((size_t)P->ncells + 1) * sizeof(double));
    Q->bounds = PyMem_Malloc((size_t)ns * sizeof(double));
    Q->order = PyMem_Malloc((size_t)ns * sizeof(int));
    pose_values(T_world_object, placement);
    if (!Q->shapes || !Q->balls || !Q->gaps || !Q->bounds || !Q->order ||
        shapes_in_object(T, q, placement, Q->shapes, Q->balls) < 0) {
        object_query_free(Q);
        PyErr_NoMemory();
        return -1;
    }
    return 0;
}

/* object_clearance(pieces, q, T_world_object, thresholds) -> (inside, distance_m, shape):
 * inside if a shape comes closer to the pieces than its threshold (0 for the links that must
 * stay out, -allowance for the contact tips); else the smallest signed distance [m] of a shape
 * whose threshold is >= 0 and that shape (-1 and inf if there is none). */
static PyObject *Tree_object_clearance(Tree *self, PyObject *args) {
    PyObject *pieces, *q_obj, *T_obj, *th_obj;
    if (!PyArg_ParseTuple(args, "OOOO:object_clearance", &pieces, &q_obj, &T_obj, &th_obj))
        return NULL;
    Py_buffer b[3];
    if (take_object_buffers(self, pieces, q_obj, T_obj, th_obj, b) < 0) return NULL;
    const Pieces *P = (const Pieces *)pieces;
    ObjectQuery Q;
    PyObject *result = NULL;
    if (object_query_init(self, P, b[0].buf, b[1].buf, &Q) == 0) {
        int inside, closest;
        double best;
        clearance_of(P, Q.shapes, Q.balls, self->ns, b[2].buf, Q.order, Q.bounds, Q.gaps,
                     &inside, &best, &closest);
        result = Py_BuildValue("Odi", inside ? Py_True : Py_False, best, closest);
        object_query_free(&Q);
    }
    release_buffers(b, 3);
    return result;
}

/* shapes_near(pieces, q, T_world_object, thresholds, out) -> int: the shapes closer to the
 * pieces than their thresholds [m], their indices into out; how many. */
static PyObject *Tree_shapes_near(Tree *self, PyObject *args) {
    PyObject *pieces, *q_obj, *T_obj, *th_obj, *out_obj;
    if (!PyArg_ParseTuple(args, "OOOOO:shapes_near", &pieces, &q_obj, &T_obj, &th_obj, &out_obj))
        return NULL;
    Py_buffer b[4];
    if (take_object_buffers(self, pieces, q_obj, T_obj, th_obj, b) < 0) return NULL;
    if (get_items(out_obj, &b[3], self->ns, 1, 1, "out") < 0) {
        release_buffers(b, 3);
        return NULL;
    }
    const Pieces *P = (const Pieces *)pieces;
    const double *thresholds = b[2].buf;
    long long *out = b[3].buf;
    ObjectQuery Q;
    PyObject *result = NULL;
    if (object_query_init(self, P, b[0].buf, b[1].buf, &Q) == 0) {
        int count = 0;
        for (int k = 0; k < self->ns; k++)
            if (shape_to_pieces(P, &Q.shapes[k], Q.balls + 4 * k, thresholds[k], thresholds[k],
                                Q.gaps) < thresholds[k])
                out[count++] = k;
        result = PyLong_FromLong(count);
        object_query_free(&Q);
    }
    release_buffers(b, 4);
    return result;
}

/* ------------------------------------------------------------------- rigid alignment -- */

/* Eigenvector of the largest eigenvalue of the symmetric 4 x 4 `N` (cyclic Jacobi rotations). */
static void largest_eigenvector(double N[4][4], double v[4]) {
    double V[4][4] = {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}};
    for (int sweep = 0; sweep < 50; sweep++) {
        double off = 0.0, scale = 0.0;
        for (int i = 0; i < 4; i++) {
            scale += N[i][i] * N[i][i];
            for (int j = i + 1; j < 4; j++) off += N[i][j] * N[i][j];
        }
        if (off <= 1e-30 * scale || off == 0.0) break;
        for (int p = 0; p < 3; p++)
            for (int q = p + 1; q < 4; q++) {
                if (N[p][q] == 0.0) continue;
                /* The rotation in the (p, q) plane that zeroes N[p][q] (Golub & Van Loan 8.4). */
                double theta = (N[q][q] - N[p][p]) / (2.0 * N[p][q]);
                double t = (theta >= 0.0 ? 1.0 : -1.0) / (fabs(theta) + sqrt(theta * theta + 1.0));
                double c = 1.0 / sqrt(t * t + 1.0), sn = t * c;
                for (int k = 0; k < 4; k++) { /* N <- N G */
                    double a = N[k][p], b = N[k][q];
                    N[k][p] = c * a - sn * b;
                    N[k][q] = sn * a + c * b;
                }
                for (int k = 0; k < 4; k++) { /* N <- G^T N */
                    double a = N[p][k], b = N[q][k];
                    N[p][k] = c * a - sn * b;
                    N[q][k] = sn * a + c * b;
                }
                for (int k = 0; k < 4; k++) { /* V <- V G */
                    double a = V[k][p], b = V[k][q];
                    V[k][p] = c * a - sn * b;
                    V[k][q] = sn * a + c * b;
                }
            }
    }
    int best = 0;
    for (int i = 1; i < 4; i++)
        if (N[i][i] > N[best][best]) best = i;
    for (int k = 0; k < 4; k++) v[k] = V[k][best];
}

/* Moves the wrist of q by the rigid motion that best maps the stack `source` (k rows) onto
 * `goal` in least squares: Horn's closed form, the rotation's quaternion being the eigenvector
 * of the largest eigenvalue of a symmetric 4 x 4 matrix of the cross-covariance (no reflection
 * can come out, unlike an SVD's). */
static void align_wrist(double *q, const double *source, const double *goal, int k) {
    double cs[3] = {0, 0, 0}, cg[3] = {0, 0, 0}, S[3][3] = {{0}};
    for (int i = 0; i < k; i++)
        for (int a = 0; a < 3; a++) cs[a] += source[3 * i + a] / k, cg[a] += goal[3 * i + a] / k;
    for (int i = 0; i < k; i++)
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++)
                S[a][b] += (source[3 * i + a] - cs[a]) * (goal[3 * i + b] - cg[b]);
    double N[4][4] = {
        {S[0][0] + S[1][1] + S[2][2], S[1][2] - S[2][1], S[2][0] - S[0][2], S[0][1] - S[1][0]},
        {S[1][2] - S[2][1], S[0][0] - S[1][1] - S[2][2], S[0][1] + S[1][0], S[2][0] + S[0][2]},
        {S[2][0] - S[0][2], S[0][1] + S[1][0], S[1][1] - S[0][0] - S[2][2], S[1][2] + S[2][1]},
        {S[0][1] - S[1][0], S[2][0] + S[0][2], S[1][2] + S[2][1], S[2][2] - S[0][0] - S[1][1]},
    };
    double e[4]; /* (w, x, y, z) */
    largest_eigenvector(N, e);
    double r[4] = {e[1], e[2], e[3], e[0]}, R[9]; /* (x, y, z, w) */
    quat_rotation(r, R);
    double p[3];
    for (int a = 0; a < 3; a++)
        p[a] = R[3 * a] * (q[0] - cs[0]) + R[3 * a + 1] * (q[1] - cs[1]) +
               R[3 * a + 2] * (q[2] - cs[2]) + cg[a];
    /* The wrist's new orientation r * w (Hamilton product, both (x, y, z, w)). */
    const double *w = q + 3;
    double o[4] = {
        r[3] * w[0] + w[3] * r[0] + r[1] * w[2] - r[2] * w[1],
        r[3] * w[1] + w[3] * r[1] + r[2] * w[0] - r[0] * w[2],
        r[3] * w[2] + w[3] * r[2] + r[0] * w[1] - r[1] * w[0],
        r[3] * w[3] - r[0] * w[0] - r[1] * w[1] - r[2] * w[2],
    };
    double norm = sqrt(o[0] * o[0] + o[1] * o[1] + o[2] * o[2] + o[3] * o[3]);
    memcpy(q, p, 3 * sizeof(double));
    for (int a = 0; a < 4; a++) q[3 + a] = o[a] / norm;
}

/* align(q, goal, fingers): q's wrist moved so that its contact stack best fits goal. */
static PyObject *Tree_align(Tree *self, PyObject *args) {
    PyObject *q_obj, *goal_obj, *fingers_obj;
    if (!PyArg_ParseTuple(args, "OOO:align", &q_obj, &goal_obj, &fingers_obj)) return NULL;
    Py_buffer b[3];
    int nf, ok = 0;
    if (take_finger_buffers(self, q_obj, 1, fingers_obj, goal_obj, 0, "goal", b, &nf) < 0)
        return NULL;
    double *stack = PyMem_Malloc(6 * (size_t)nf * sizeof(double) + 1);
    if (nf < 1) {
        PyErr_SetString(PyExc_ValueError, "fingers must not be empty");
    } else if (stack == NULL) {
        PyErr_NoMemory();
    } else if (stack_at(self, b[1].buf, b[0].buf, nf, stack) == 0) {
        align_wrist(b[1].buf, stack, b[2].buf, 2 * nf);
        ok = 1;
    }
    PyMem_Free(stack);
    release_buffers(b, 3);
    if (!ok) return NULL;
    Py_RETURN_NONE;
}

/* ------------------------------------------------------------------ database keys -- */

/* rigid_key(points, normals, normal_scale, out): sahgrasp/ik/learned.py's rigid_features of
 * one contact set (F >= 3 rows): the points and normal_scale times the normals in the contacts'
 * own frame (origin their centroid, x towards the first, y along the last minus the second). */
static PyObject *rigid_key(PyObject *module, PyObject *args) {
    PyObject *p_obj, *n_obj, *out_obj;
    double scale;
    if (!PyArg_ParseTuple(args, "OOdO:rigid_key", &p_obj, &n_obj, &scale, &out_obj)) return NULL;
    Py_buffer pb, nb, ob;
    if (get_items(p_obj, &pb, -1, 0, 0, "points") < 0) return NULL;
    int nf = (int)(pb.len / 24), ok = 0;
    if (nf < 3 || pb.len != 24 * (Py_ssize_t)nf) {
        PyErr_SetString(PyExc_ValueError, "points must hold F >= 3 rows of 3");
        PyBuffer_Release(&pb);
        return NULL;
    }
    if (get_items(n_obj, &nb, 3 * nf, 0, 0, "normals") < 0) goto release_p;
    if (get_items(out_obj, &ob, 6 * nf, 0, 1, "out") < 0) goto release_n;
    const double *p = pb.buf, *n = nb.buf;
    double *out = ob.buf, c[3] = {0, 0, 0}, x[3], y[3], z[3], side[3];
    for (int i = 0; i < nf; i++)
        for (int a = 0; a < 3; a++) c[a] += p[3 * i + a];
    for (int a = 0; a < 3; a++) {
        c[a] /= nf;
        x[a] = p[a] - c[a];
        side[a] = p[3 * (nf - 1) + a] - p[3 + a];
    }
    double norm = fmax(sqrt(dot(x, x, 3)), 1e-12), along;
    for (int a = 0; a < 3; a++) x[a] /= norm;
    along = dot(side, x, 3);
    for (int a = 0; a < 3; a++) y[a] = side[a] - along * x[a];
    norm = fmax(sqrt(dot(y, y, 3)), 1e-12);
    for (int a = 0; a < 3; a++) y[a] /= norm;
    cross(x, y, z);
    const double *axes[3] = {x, y, z};
    for (int i = 0; i < nf; i++) {
        double d[3] = {p[3 * i] - c[0], p[3 * i + 1] - c[1], p[3 * i + 2] - c[2]};
        for (int a = 0; a < 3; a++) {
            out[3 * i + a] = dot(d, axes[a], 3);
            out[3 * (nf + i) + a] = scale * dot(n + 3 * i, axes[a], 3);
        }
    }
    ok = 1;
    PyBuffer_Release(&ob);
release_n:
    PyBuffer_Release(&nb);
release_p:
    PyBuffer_Release(&pb);
    if (!ok) return NULL;
    Py_RETURN_NONE;
}

static PyMethodDef module_methods[] = {
    {"rigid_key", rigid_key, METH_VARARGS,
     "rigid_key(points, normals, normal_scale, out): the rigid-invariant key of one contact set."},
    {NULL, NULL, 0, NULL},
};

static PyMethodDef Tree_methods[] = {
    {"solve", (PyCFunction)Tree_solve, METH_VARARGS,
     "solve(q, target, fingers, max_iterations, refine_m, d_min_m, stall, history) -> "
     "(outcome, iterations, error_m); q is updated in place."},
    {"stack", (PyCFunction)Tree_stack, METH_VARARGS,
     "stack(q, fingers, stack_out, jacobian_out_or_None): contact stack and its Jacobian."},
    {"errors", (PyCFunction)Tree_errors, METH_VARARGS,
     "errors(q, target, fingers, out): per finger, the contact point's and then the sphere "
     "centre's distance from the target's [m]."},
    {"integrate", (PyCFunction)Tree_integrate, METH_VARARGS,
     "integrate(q, v, out, clamp): q (+) v, joints clamped to their limits if clamp."},
    {"repair", (PyCFunction)Tree_repair, METH_VARARGS,
     "repair(q, target, fingers, joints, points, normals, depths, out) -> bool: one collision "
     "repair step into out; False if its rows are degenerate."},
    {"set_shapes", (PyCFunction)(void (*)(void))Tree_set_shapes, METH_VARARGS | METH_KEYWORDS,
     "set_shapes(*, joints, placements, kinds, sizes, balls, pairs): the collision shapes and the "
     "pairs the self-collision verdicts check."},
    {"pairs_within", (PyCFunction)Tree_pairs_within, METH_VARARGS,
     "pairs_within(q, margin_m, out) -> int: the checked pairs closer than margin_m at q "
     "(indices into out, at most len(out)); how many."},
    {"object_clearance", (PyCFunction)Tree_object_clearance, METH_VARARGS,
     "object_clearance(pieces, q, T_world_object, thresholds) -> (inside, distance_m, shape)."},
    {"shapes_near", (PyCFunction)Tree_shapes_near, METH_VARARGS,
     "shapes_near(pieces, q, T_world_object, thresholds, out) -> int: the shapes closer to the "
     "pieces than their thresholds, their indices into out; how many."},
    {"align", (PyCFunction)Tree_align, METH_VARARGS,
     "align(q, goal, fingers): q's wrist moved (in place) by the rigid motion that best maps "
     "its contact stack onto goal."},
    {NULL, NULL, 0, NULL},
};

static PyMemberDef Tree_members[] = {
    {"shape_count", T_INT, offsetof(Tree, ns), READONLY, "collision shapes set (set_shapes)"},
    {"pair_count", T_INT, offsetof(Tree, npairs), READONLY, "shape pairs checked (set_shapes)"},
    {NULL, 0, 0, 0, NULL},
};

static PyTypeObject TreeType = {
    PyVarObject_HEAD_INIT(NULL, 0).tp_name = "sahgrasp.ik._lm.Tree",
    .tp_basicsize = sizeof(Tree),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "A hand's kinematic tree and the compiled Levenberg-Marquardt loop of the IK.",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)Tree_init,
    .tp_dealloc = (destructor)Tree_dealloc,
    .tp_methods = Tree_methods,
    .tp_members = Tree_members,
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT,
    .m_name = "sahgrasp.ik._lm",
    .m_doc = "Compiled Levenberg-Marquardt loop of the IK.",
    .m_size = -1, .m_methods = module_methods,
};

PyMODINIT_FUNC PyInit__lm(void) {
    static PyTypeObject *types[] = {&TreeType, &PiecesType, NULL};
    /* The Python side (sahgrasp/ik/compiled.py) reads these, never a copy. */
    static const IntConstant constants[] = {
        {"CONVERGED", CONVERGED},
        {"NO_PROGRESS", NO_PROGRESS},
        {"MAX_ITERATIONS", MAX_ITERATIONS},
        {"SHAPE_POINT", SHAPE_POINT},
        {"SHAPE_BOX", SHAPE_BOX},
        {"SHAPE_CYLINDER", SHAPE_CYLINDER},
        {"SHAPE_ELLIPSOID", SHAPE_ELLIPSOID},
        {"SHAPE_CONVEX", SHAPE_CONVEX},
        {"FIXED_JOINT", FIXED_JOINT},
        {NULL, 0},
    };
    return create_module(&module, types, constants);
}

/* Compiled parts of the quality indices (see quality.py): the last columns of Q from a stack of
 * Householder QR factorisations, and the semi-axes of the manipulability ellipsoids.
 *
 * The manipulability indices need the null space of a full-row-rank Jacobian J (m x n) at every
 * chart centre: the last n - m columns of Q in J^T = Q R. numpy.linalg.qr forms all of Q, one
 * LAPACK call per matrix (dorgqr), which was more than half of the time of the planar hand's
 * indices; here numpy's raw factorisation is kept and only the n - m columns wanted are formed,
 * by applying the m reflectors to the last n - m columns of the identity. The semi-axes took two
 * numpy SVDs per stack of small matrices (6 x 3 and 3 x 3 for the planar hand), about 4 us a
 * matrix in numpy's per-matrix LAPACK calls; here one-sided Jacobi (Hestenes), which keeps the
 * singular values' relative accuracy, on each.
 *
 * It is compiled beside the atlas's polytopes but serves quality.py (the same layer); a
 * top-level sahgrasp._quality needs a row in docs/architecture.md's layer table.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

#include "../_arrays.h"


/* orthogonal_tail(h, tau, out): see _quality.pyi. */
static PyObject *orthogonal_tail(PyObject *mod, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "orthogonal_tail(h, tau, out) takes 3 arguments");
        return NULL;
    }
    static const char *names[3] = {"h", "tau", "out"};
    static const int dims[3] = {3, 2, 3};
    Py_buffer views[3];
    int got = 0;
    PyObject *result = NULL;
    for (; got < 3; got++)
        if (get_array(args[got], &views[got], dims[got], 0, got == 2, names[got]) < 0) goto done;
    Py_ssize_t count = views[0].shape[0], m = views[0].shape[1], n = views[0].shape[2];
    Py_ssize_t rest = n - m;
    if (m < 1 || rest < 1) {
        PyErr_Format(PyExc_ValueError,
                     "orthogonal_tail needs h of shape (B, m, n) with 1 <= m < n, got (%zd, %zd, "
                     "%zd)", count, m, n);
        goto done;
    }
    const Py_ssize_t tau_shape[2] = {count, m}, out_shape[3] = {count, n, rest};
    if (check_shape(&views[1], 2, tau_shape, "tau") < 0 ||
        check_shape(&views[2], 3, out_shape, "out") < 0)
        goto done;
    const double *h_all = views[0].buf, *tau_all = views[1].buf;
    double *out_all = views[2].buf;
    for (Py_ssize_t b = 0; b < count; b++) {
        const double *h = h_all + b * m * n, *tau = tau_all + b * m;
        double *q = out_all + b * n * rest; /* row-major n x rest */
        memset(q, 0, sizeof(double) * (size_t)(n * rest));
        for (Py_ssize_t c = 0; c < rest; c++) q[(m + c) * rest + c] = 1.0;
        /* Q = H_0 H_1 ... H_{m-1}, H_i = I - tau_i v_i v_i^T with v_i = (0, .., 0, 1, h[i, i+1:]):
         * apply H_{m-1} first. Rows above i are untouched by H_i. */
        for (Py_ssize_t i = m - 1; i >= 0; i--) {
            const double *v = h + i * n;
            for (Py_ssize_t c = 0; c < rest; c++) {
                double w = q[i * rest + c];
                for (Py_ssize_t r = i + 1; r < n; r++) w += v[r] * q[r * rest + c];
                w *= tau[i];
                q[i * rest + c] -= w;
                for (Py_ssize_t r = i + 1; r < n; r++) q[r * rest + c] -= w * v[r];
            }
        }
    }
    result = Py_None;
    Py_INCREF(result);
done:
    for (int i = 0; i < got; i++) PyBuffer_Release(&views[i]);
    return result;
}

/* One-sided Jacobi (Hestenes) on the columns of the rows x cols matrix a (row-major, destroyed):
 * afterwards its columns are orthogonal, their norms the singular values, and v (cols x cols,
 * row-major, set here; NULL for none) holds the rotations: a_in v = a_out. */
static void hestenes(double *a, Py_ssize_t rows, Py_ssize_t cols, double *v) {
    if (v != NULL) {
        memset(v, 0, sizeof(double) * (size_t)(cols * cols));
        for (Py_ssize_t i = 0; i < cols; i++) v[i * cols + i] = 1.0;
    }
    for (int sweep = 0; sweep < 60; sweep++) {
        int rotated = 0;
        for (Py_ssize_t p = 0; p < cols; p++) {
            for (Py_ssize_t q = p + 1; q < cols; q++) {
                double app = 0.0, aqq = 0.0, apq = 0.0;
                for (Py_ssize_t r = 0; r < rows; r++) {
                    double x = a[r * cols + p], y = a[r * cols + q];
                    app += x * x;
                    aqq += y * y;
                    apq += x * y;
                }
                if (apq == 0.0 || fabs(apq) <= 1e-15 * sqrt(app * aqq)) continue;
                rotated = 1;
                double zeta = (aqq - app) / (2.0 * apq);
                double t = (zeta >= 0.0 ? 1.0 : -1.0) / (fabs(zeta) + sqrt(1.0 + zeta * zeta));
                double c = 1.0 / sqrt(1.0 + t * t), s = c * t;
                for (Py_ssize_t r = 0; r < rows; r++) {
                    double x = a[r * cols + p], y = a[r * cols + q];
                    a[r * cols + p] = c * x - s * y;
                    a[r * cols + q] = s * x + c * y;
                }
                for (Py_ssize_t r = 0; v != NULL && r < cols; r++) {
                    double x = v[r * cols + p], y = v[r * cols + q];
                    v[r * cols + p] = c * x - s * y;
                    v[r * cols + q] = s * x + c * y;
                }
            }
        }
        if (!rotated) break;
    }
}

/* The norms of a's columns (rows x cols, row-major) in norms, and their order, largest first, in
 * order (insertion sort: a handful of columns). */
static void column_norms(const double *a, Py_ssize_t rows, Py_ssize_t cols, double *norms,
                         Py_ssize_t *order) {
    for (Py_ssize_t c = 0; c < cols; c++) {
        double s = 0.0;
        for (Py_ssize_t r = 0; r < rows; r++) s += a[r * cols + c] * a[r * cols + c];
        norms[c] = sqrt(s);
        Py_ssize_t at = c;
        while (at > 0 && norms[order[at - 1]] < norms[c]) {
            order[at] = order[at - 1];
            at--;
        }
        order[at] = c;
    }
}

/* semi_axes(actuated, obj, out, rank_tol): see _quality.pyi. */
static PyObject *semi_axes(PyObject *mod, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 4) {
        PyErr_SetString(PyExc_TypeError,
                        "semi_axes(actuated, obj, out, rank_tol) takes 4 arguments");
        return NULL;
    }
    double rank_tol = PyFloat_AsDouble(args[3]);
    if (rank_tol == -1.0 && PyErr_Occurred()) return NULL;
    static const char *names[3] = {"actuated", "obj", "out"};
    static const int dims[3] = {3, 3, 2};
    Py_buffer views[3];
    int got = 0;
    PyObject *result = NULL;
    double *work = NULL;
    Py_ssize_t *order = NULL;
    for (; got < 3; got++)
        if (get_array(args[got], &views[got], dims[got], 0, got == 2, names[got]) < 0) goto done;
    Py_ssize_t count = views[0].shape[0], na = views[0].shape[1], t = views[0].shape[2];
    Py_ssize_t no = views[1].shape[1];
    if (t < 1 || na < 1 || no < 1) {
        PyErr_Format(PyExc_ValueError,
                     "semi_axes needs actuated (B, a, t) and obj (B, o, t) with a, o, t >= 1, got "
                     "a = %zd, o = %zd, t = %zd", na, no, t);
        goto done;
    }
    const Py_ssize_t obj_shape[3] = {count, no, t}, out_shape[2] = {count, no};
    if (check_shape(&views[1], 3, obj_shape, "obj") < 0 ||
        check_shape(&views[2], 2, out_shape, "out") < 0)
        goto done;
    Py_ssize_t thin = na < t ? na : t; /* the thin SVD's singular values of A */
    work = PyMem_Malloc(sizeof(double) * (size_t)(na * t + t * t + no * thin + 2 * t));
    order = PyMem_Malloc(sizeof(Py_ssize_t) * (size_t)t);
    if (work == NULL || order == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    double *a = work, *v = a + na * t, *m = v + t * t, *s = m + no * thin, *sigma = s + t;
    const double *a_all = views[0].buf, *b_all = views[1].buf;
    double *out_all = views[2].buf;
    for (Py_ssize_t i = 0; i < count; i++) {
        const double *b = b_all + i * no * t;
        double *out = out_all + i * no;
        memcpy(a, a_all + i * na * t, sizeof(double) * (size_t)(na * t));
        hestenes(a, na, t, v); /* A V = U S */
        column_norms(a, na, t, s, order);
        memset(out, 0, sizeof(double) * (size_t)no);
        double largest = s[order[0]], smallest = s[order[thin - 1]];
        if (smallest <= rank_tol * largest) continue; /* A rank deficient: no ellipsoid */
        for (Py_ssize_t r = 0; r < no; r++) { /* M = B V S^-1 over the thin singular vectors */
            for (Py_ssize_t c = 0; c < thin; c++) {
                Py_ssize_t col = order[c];
                double sum = 0.0;
                for (Py_ssize_t j = 0; j < t; j++) sum += b[r * t + j] * v[j * t + col];
                m[r * thin + c] = sum / s[col];
            }
        }
        hestenes(m, no, thin, NULL);
        column_norms(m, no, thin, sigma, order);
        for (Py_ssize_t c = 0; c < thin && c < no; c++) out[c] = sigma[order[c]];
    }
    result = Py_None;
    Py_INCREF(result);
done:
    PyMem_Free(work);
    PyMem_Free(order);
    for (int i = 0; i < got; i++) PyBuffer_Release(&views[i]);
    return result;
}

static PyMethodDef methods[] = {
    {"orthogonal_tail", (PyCFunction)(void (*)(void))orthogonal_tail, METH_FASTCALL,
     "orthogonal_tail(h, tau, out): the last n - m columns of Q from numpy.linalg.qr's raw "
     "factorisation (h, tau)."},
    {"semi_axes", (PyCFunction)(void (*)(void))semi_axes, METH_FASTCALL,
     "semi_axes(actuated, obj, out, rank_tol): the manipulability ellipsoids' semi-axes."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT,
    .m_name = "sahgrasp.atlas._quality",
    .m_doc = "Null-space columns of stacked QR factorisations and ellipsoid semi-axes (quality.py).",
    .m_size = -1,
    .m_methods = methods,
};

PyMODINIT_FUNC PyInit__quality(void) { return create_module(&module, NULL, NULL); }

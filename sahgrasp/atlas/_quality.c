/* The last columns of Q from a stack of Householder QR factorisations (see quality.py).
 *
 * The manipulability indices need the null space of a full-row-rank Jacobian J (m x n) at every
 * chart centre: the last n - m columns of Q in J^T = Q R. numpy.linalg.qr forms all of Q, one
 * LAPACK call per matrix (dorgqr), which was more than half of the time of the planar hand's
 * indices; here numpy's raw factorisation is kept and only the n - m columns wanted are formed,
 * by applying the m reflectors to the last n - m columns of the identity.
 *
 * It is compiled beside the atlas's polytopes but serves quality.py (the same layer); a
 * top-level sahgrasp._quality needs a row in docs/architecture.md's layer table.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <string.h>

/* A C-contiguous float64 buffer of ``ndim`` dimensions (writable if asked): 0, or -1 with an
 * exception. */
static int get_array(PyObject *obj, Py_buffer *view, int ndim, int writable, const char *what) {
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, view, flags) < 0) return -1;
    if (view->ndim != ndim || view->itemsize != sizeof(double) || view->format == NULL ||
        strcmp(view->format, "d") != 0) {
        PyErr_Format(PyExc_TypeError, "%s must be a C-contiguous float64 array of %d dimensions",
                     what, ndim);
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

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
        if (get_array(args[got], &views[got], dims[got], got == 2, names[got]) < 0) goto done;
    Py_ssize_t count = views[0].shape[0], m = views[0].shape[1], n = views[0].shape[2];
    Py_ssize_t rest = n - m;
    if (m < 1 || rest < 1 || views[1].shape[0] != count || views[1].shape[1] != m ||
        views[2].shape[0] != count || views[2].shape[1] != n || views[2].shape[2] != rest) {
        PyErr_Format(PyExc_ValueError,
                     "orthogonal_tail needs h (B, m, n) with 1 <= m < n, tau (B, m) and out "
                     "(B, n, n - m)");
        goto done;
    }
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

static PyMethodDef methods[] = {
    {"orthogonal_tail", (PyCFunction)(void (*)(void))orthogonal_tail, METH_FASTCALL,
     "orthogonal_tail(h, tau, out): the last n - m columns of Q from numpy.linalg.qr's raw "
     "factorisation (h, tau)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT,
    .m_name = "sahgrasp.atlas._quality",
    .m_doc = "The last columns of Q from stacked Householder QR factorisations (see quality.py).",
    .m_size = -1,
    .m_methods = methods,
};

PyMODINIT_FUNC PyInit__quality(void) { return PyModule_Create(&module); }

/* The planar hand's Jacobian and the terms its F is linear in (see planar.py), compiled.
 *
 * The atlas's Newton steps and tangent spaces ask for F and J at a few points at a time, about
 * 430 times each per atlas of the paper's size; in numpy each was some 20 array operations per
 * call, 20-36 us, against well under 1 us of arithmetic per point. The entries are computed with
 * the operations numpy applied, in the same order (no fused multiply-add: setup.py passes
 * -ffp-contract=off), and the C library's sin and cos, which gave numpy's float64 sin and cos
 * bit for bit on 100 000 random angles: the same doubles, hence the same atlases. arctan2, for
 * which numpy has code of its own, and F's matrix product stay in numpy.
 *
 * It is compiled beside the atlas's polytopes but belongs to the planar hand: the atlas code
 * never uses it (a top-level sahgrasp._planar needs a row in docs/architecture.md's layer table).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "../_arrays.h"

#define N_VARS 19 /* 12 phalanx vectors, t_o (2), v_o (2), u (3) */
#define GRASP_VALUES 29 /* variable entries of the grasp equations' Jacobian */
#define FEATURES 56     /* the terms F is linear in (planar.py, PlanarGraspProblem.F) */

/* jacobian(x, constant, where, radii, rates, out): see _planar.pyi. */
static PyObject *jacobian(PyObject *mod, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 6) {
        PyErr_SetString(PyExc_TypeError,
                        "jacobian(x, constant, where, radii, rates, out) takes 6 arguments");
        return NULL;
    }
    static const char *names[6] = {"x", "constant", "where", "radii", "rates", "out"};
    static const int dims[6] = {2, 1, 1, 1, 2, 3};
    Py_buffer views[6];
    int got = 0;
    PyObject *result = NULL;
    for (; got < 6; got++)
        if (get_array(args[got], &views[got], dims[got], got == 2, got == 5, names[got]) < 0)
            goto done;
    /* x (B, N_VARS), constant (size,), where (values,), radii (3,), rates (s, 12) and out
     * (B, rows, N_VARS), for s = len(rates). */
    Py_ssize_t count = views[0].shape[0], s = views[4].shape[0];
    Py_ssize_t rows = 16 + s, size = rows * N_VARS, values = GRASP_VALUES + 12 * s;
    const Py_ssize_t shapes[6][3] = {{count, N_VARS}, {size}, {values}, {3}, {s, 12},
                                     {count, rows, N_VARS}};
    for (int i = 0; i < 6; i++)
        if (check_shape(&views[i], dims[i], shapes[i], names[i]) < 0) goto done;
    const double *x_all = views[0].buf, *constant = views[1].buf, *radii = views[3].buf,
                 *rates = views[4].buf;
    const int64_t *where = views[2].buf;
    for (Py_ssize_t i = 0; i < values; i++) {
        if (where[i] < 0 || where[i] >= size) {
            PyErr_Format(PyExc_ValueError, "where[%zd] = %lld lies outside the Jacobian", i,
                         (long long)where[i]);
            goto done;
        }
    }
    double *out = views[5].buf;
    for (Py_ssize_t b = 0; b < count; b++) {
        const double *x = x_all + b * N_VARS;
        double *jac = out + b * size, value[GRASP_VALUES], *v = value, su[3], cu[3];
        memcpy(jac, constant, sizeof(double) * (size_t)size);
        for (int i = 0; i < 3; i++) {
            su[i] = sin(x[16 + i]);
            cu[i] = cos(x[16 + i]);
        }
        for (int i = 0; i < 12; i++) *v++ = 2.0 * x[i]; /* Eq. (19) */
        for (int i = 14; i < 16; i++) *v++ = 2.0 * x[i]; /* Eq. (20) */
        for (int i = 0; i < 3; i++) *v++ = radii[i] * su[i]; /* Eq. (7), d/du_i: x, then y */
        for (int i = 0; i < 3; i++) *v++ = -radii[i] * cu[i];
        for (int i = 0; i < 3; i++) *v++ = -su[i]; /* Eq. (8), d/dv_{i,2}: x, then y */
        for (int i = 0; i < 3; i++) *v++ = cu[i];
        for (int i = 0; i < 3; i++) /* Eq. (8), d/du_i; distal phalanx (x[4i+2], x[4i+3]) */
            *v++ = -su[i] * x[4 * i + 3] - cu[i] * x[4 * i + 2];
        double grad[12]; /* each phalanx angle by its vector: (-v_y, v_x) / |v|^2 */
        for (int p = 0; p < 6; p++) {
            double vx = x[2 * p], vy = x[2 * p + 1], norm2 = vx * vx + vy * vy;
            grad[2 * p] = -vy / norm2;
            grad[2 * p + 1] = vx / norm2;
        }
        const int64_t *motion = where + GRASP_VALUES;
        for (Py_ssize_t r = 0; r < s; r++) /* Eq. (13): E_s^T J_a */
            for (int j = 0; j < 12; j++) jac[motion[12 * r + j]] = rates[12 * r + j] * grad[j];
        for (Py_ssize_t i = 0; i < GRASP_VALUES; i++) jac[where[i]] = value[i];
    }
    result = Py_None;
    Py_INCREF(result);
done:
    for (int i = 0; i < got; i++) PyBuffer_Release(&views[i]);
    return result;
}

/* features(x, reference, out, cosines): see _planar.pyi. */
static PyObject *features(PyObject *mod, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 4) {
        PyErr_SetString(PyExc_TypeError, "features(x, reference, out, cosines) takes 4 arguments");
        return NULL;
    }
    static const char *names[4] = {"x", "reference", "out", "cosines"};
    static const int dims[4] = {2, 1, 2, 2};
    Py_buffer views[4];
    int got = 0;
    PyObject *result = NULL;
    for (; got < 4; got++)
        if (get_array(args[got], &views[got], dims[got], 0, got >= 2, names[got]) < 0) goto done;
    Py_ssize_t count = views[0].shape[0];
    const Py_ssize_t shapes[4][2] = {{count, N_VARS}, {N_VARS}, {count, FEATURES}, {count, 6}};
    for (int i = 0; i < 4; i++)
        if (check_shape(&views[i], dims[i], shapes[i], names[i]) < 0) goto done;
    const double *x_all = views[0].buf, *ref = views[1].buf;
    double *out_all = views[2].buf, *cos_all = views[3].buf;
    for (Py_ssize_t b = 0; b < count; b++) {
        const double *x = x_all + b * N_VARS;
        double *out = out_all + b * FEATURES, *cosine = cos_all + 6 * b;
        for (int i = 0; i < N_VARS; i++) {
            out[i] = x[i];
            out[N_VARS + i] = x[i] * x[i];
        }
        for (int i = 0; i < 3; i++) { /* w(u_i), Eq. (24), and its products with v_{i,2} */
            double cu = cos(x[16 + i]), su = sin(x[16 + i]);
            out[38 + i] = cu;
            out[41 + i] = su;
            out[44 + i] = cu * x[4 * i + 3];
            out[47 + i] = su * x[4 * i + 2];
        }
        for (int p = 0; p < 6; p++) { /* each phalanx's turn from the reference: its sine part */
            double rx = ref[2 * p], ry = ref[2 * p + 1], vx = x[2 * p], vy = x[2 * p + 1];
            out[50 + p] = rx * vy - ry * vx;
            cosine[p] = rx * vx + ry * vy;
        }
    }
    result = Py_None;
    Py_INCREF(result);
done:
    for (int i = 0; i < got; i++) PyBuffer_Release(&views[i]);
    return result;
}

static PyMethodDef methods[] = {
    {"jacobian", (PyCFunction)(void (*)(void))jacobian, METH_FASTCALL,
     "jacobian(x, constant, where, radii, rates, out): the planar hand's Jacobian at each row "
     "of x."},
    {"features", (PyCFunction)(void (*)(void))features, METH_FASTCALL,
     "features(x, reference, out, cosines): the terms F is linear in, turns as sine and cosine "
     "parts."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT,
    .m_name = "sahgrasp.atlas._planar",
    .m_doc = "The planar hand's Jacobian and the terms of its F, compiled (see planar.py).",
    .m_size = -1,
    .m_methods = methods,
};

PyMODINIT_FUNC PyInit__planar(void) { return create_module(&module, NULL, NULL); }

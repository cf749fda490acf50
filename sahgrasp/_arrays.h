/* The conventions the compiled modules share (atlas/_polytope.c, atlas/_planar.c,
 * atlas/_quality.c, ik/_lm.c); docs/contributing.md, "The C extensions' conventions".
 *
 * Arguments: numpy arrays reach the modules through the buffer protocol and every one is read
 * by get_array or get_items below (check_shape for a shape that follows from another array),
 * which check its type, item type, contiguity, writability and shape, and name the array at
 * fault in the error:
 *   TypeError  "NAME must be a C-contiguous float64 array ..., got ..." (not an array, wrong item
 *              type, not C-contiguous, read-only where written);
 *   ValueError "NAME: expected ..., got ..." (wrong number of dimensions, shape or size), and
 *              the entry points' own checks of values ("NAME[i] = v lies outside ...").
 * Allocation: every buffer a module owns is taken with PyMem_Malloc / PyMem_Calloc /
 * PyMem_Realloc and given back with PyMem_Free, with the GIL held; a failed allocation raises
 * MemoryError through PyErr_NoMemory. Code run without the GIL (Tree.solve's loop between
 * Py_BEGIN_ALLOW_THREADS and Py_END_ALLOW_THREADS) only uses buffers taken before it.
 * Constants the Python side needs (shape kinds, outcome codes) are module constants added by
 * PyModule_AddIntConstant from the C enums: the Python side reads them, never a copy. */
#ifndef SAHGRASP_ARRAYS_H
#define SAHGRASP_ARRAYS_H

#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <limits.h>
#include <string.h>

/* Whether a buffer's item format is float64 ('d') or int64 (numpy's 'l' where a C long has 64
 * bits, 'q' elsewhere), with numpy's optional native byte-order prefix. */
static inline int array_format_is(const Py_buffer *view, int integer) {
    const char *format = view->format == NULL ? "B" : view->format;
    if (format[0] == '=' || format[0] == '@' || format[0] == (PY_LITTLE_ENDIAN ? '<' : '>'))
        format++;
    if (view->itemsize != 8) return 0;
    return integer ? strcmp(format, "l") == 0 || strcmp(format, "q") == 0
                   : strcmp(format, "d") == 0;
}

/* A C-contiguous buffer of ``ndim`` dimensions (any number if ``ndim`` < 0) whose items are
 * float64 (or int64 when ``integer``), writable when asked: 0 with ``view`` held (the caller
 * releases it), or -1 with the error named after ``what`` and nothing held. */
static inline int get_array(PyObject *obj, Py_buffer *view, int ndim, int integer, int writable,
                     const char *what) {
    const char *dtype = integer ? "int64" : "float64";
    if (!PyObject_CheckBuffer(obj)) {
        PyErr_Format(PyExc_TypeError, "%s must be a C-contiguous %s array, got %.100s", what,
                     dtype, Py_TYPE(obj)->tp_name);
        return -1;
    }
    if (PyObject_GetBuffer(obj, view, PyBUF_RECORDS_RO) < 0) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "%s must be a C-contiguous %s array, got a %.100s whose "
                     "items cannot be read", what, dtype, Py_TYPE(obj)->tp_name);
        return -1;
    }
    const char *problem = NULL;
    if (!array_format_is(view, integer))
        problem = "items of another type";
    else if (!PyBuffer_IsContiguous(view, 'C'))
        problem = "a non-contiguous array (np.ascontiguousarray makes one)";
    else if (writable && view->readonly)
        problem = "a read-only array (it is written)";
    if (problem != NULL) {
        PyErr_Format(PyExc_TypeError, "%s must be a %sC-contiguous %s array, got %s (format "
                     "'%s', %zd bytes each)", what, writable ? "writable " : "", dtype, problem,
                     view->format == NULL ? "B" : view->format, view->itemsize);
        PyBuffer_Release(view);
        return -1;
    }
    if (ndim >= 0 && view->ndim != ndim) {
        PyErr_Format(PyExc_ValueError, "%s: expected a %s array of %d dimensions, got %d", what,
                     dtype, ndim, view->ndim);
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

/* get_array of any shape holding ``n`` items (any number if ``n`` < 0). */
static inline int get_items(PyObject *obj, Py_buffer *view, Py_ssize_t n, int integer, int writable,
                     const char *what) {
    if (get_array(obj, view, -1, integer, writable, what) < 0) return -1;
    if (n >= 0 && view->len != n * view->itemsize) {
        PyErr_Format(PyExc_ValueError, "%s: expected %zd values, got %zd", what, n,
                     view->len / view->itemsize);
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

/* 0 if the held ``view`` has the ``ndim`` dimensions of ``shape`` (-1: any length on that
 * axis), or -1 with a ValueError naming ``what`` (the view stays held: the caller releases it). */
static inline int check_shape(const Py_buffer *view, int ndim, const Py_ssize_t *shape,
                              const char *what) {
    int ok = view->ndim == ndim;
    for (int d = 0; d < ndim && ok; d++) ok = shape[d] < 0 || view->shape[d] == shape[d];
    if (ok) return 0;
    char expected[200] = "", got[200] = "";
    for (int d = 0; d < ndim; d++) {
        size_t used = strlen(expected);
        if (shape[d] >= 0)
            PyOS_snprintf(expected + used, sizeof expected - used, "%s%zd", d ? ", " : "",
                          shape[d]);
        else
            PyOS_snprintf(expected + used, sizeof expected - used, "%sany", d ? ", " : "");
    }
    for (int d = 0; d < view->ndim && d < 8; d++) {
        size_t used = strlen(got);
        PyOS_snprintf(got + used, sizeof got - used, "%s%zd", d ? ", " : "", view->shape[d]);
    }
    PyErr_Format(PyExc_ValueError, "%s: expected shape (%s%s), got (%s%s)", what, expected,
                 ndim == 1 ? "," : "", got, view->ndim == 1 ? "," : "");
    return -1;
}

/* An int argument ``obj`` in [low, high] into ``out``: 0, or -1 with a TypeError (not an
 * integer) or a ValueError (out of range) naming ``what``. */
static inline int get_int(PyObject *obj, int *out, long low, long high, const char *what) {
    PyObject *index = PyIndex_Check(obj) ? PyNumber_Index(obj) : NULL;
    if (index == NULL) {
        if (!PyErr_Occurred() || PyErr_ExceptionMatches(PyExc_TypeError)) {
            PyErr_Clear();
            PyErr_Format(PyExc_TypeError, "%s must be an integer, got %.100s", what,
                         Py_TYPE(obj)->tp_name);
        }
        return -1;
    }
    int overflow = 0;
    long value = PyLong_AsLongAndOverflow(index, &overflow);
    Py_DECREF(index);
    if (value == -1 && PyErr_Occurred()) return -1;
    if (overflow != 0 || value < low || value > high) {
        PyErr_Format(PyExc_ValueError, "%s must be an integer in [%ld, %ld], got %R", what, low,
                     high, obj);
        return -1;
    }
    *out = (int)value;
    return 0;
}

/* Module boilerplate: a module's int constants, a table ended by a NULL name. */
typedef struct {
    const char *name;
    long value;
} IntConstant;

/* The module ``def`` with its ``types`` (NULL-ended) and ``constants``: the new module, or NULL
 * with the error set. */
static inline PyObject *create_module(PyModuleDef *def, PyTypeObject **types,
                               const IntConstant *constants) {
    for (PyTypeObject **t = types; t != NULL && *t != NULL; t++)
        if (PyType_Ready(*t) < 0) return NULL;
    PyObject *m = PyModule_Create(def);
    if (m == NULL) return NULL;
    for (PyTypeObject **t = types; t != NULL && *t != NULL; t++) {
        const char *dot = strrchr((*t)->tp_name, '.');
        Py_INCREF(*t);
        if (PyModule_AddObject(m, dot == NULL ? (*t)->tp_name : dot + 1, (PyObject *)*t) < 0) {
            Py_DECREF(*t);
            Py_DECREF(m);
            return NULL;
        }
    }
    for (const IntConstant *c = constants; c != NULL && c->name != NULL; c++)
        if (PyModule_AddIntConstant(m, c->name, c->value) < 0) {
            Py_DECREF(m);
            return NULL;
        }
    return m;
}

#endif

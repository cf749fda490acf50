/* The buffer check the compiled modules share (atlas/_polytope.c, atlas/_planar.c,
 * atlas/_quality.c, ik/_lm.c): numpy arrays reach them through the buffer protocol. */
#ifndef SAHGRASP_ARRAYS_H
#define SAHGRASP_ARRAYS_H

#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <string.h>

/* A C-contiguous buffer of ``ndim`` dimensions (any number if ``ndim`` < 0) whose items are
 * float64 (or int64 when ``integer``: numpy's 'l' where a C long has 64 bits, 'q' elsewhere),
 * writable when asked: 0, or -1 with a TypeError naming ``what``. */
static int get_array(PyObject *obj, Py_buffer *view, int ndim, int integer, int writable,
                     const char *what) {
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, view, flags) < 0) return -1;
    const char *format = view->format == NULL ? "" : view->format;
    int ok = (ndim < 0 || view->ndim == ndim) && view->itemsize == 8 &&
             (integer ? strcmp(format, "l") == 0 || strcmp(format, "q") == 0
                      : strcmp(format, "d") == 0);
    if (!ok) {
        if (ndim < 0)
            PyErr_Format(PyExc_TypeError, "%s must be a C-contiguous %s array", what,
                         integer ? "int64" : "float64");
        else
            PyErr_Format(PyExc_TypeError, "%s must be a C-contiguous %s array of %d dimensions",
                         what, integer ? "int64" : "float64", ndim);
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

#endif

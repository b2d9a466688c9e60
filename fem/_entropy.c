/* flexcal.fem._entropy: a fixed entropy source for fTetWild, so that its meshes repeat.
 *
 * fTetWild draws its random seed from std::random_device (pytetwild 0.4.2 exposes no
 * seed), so the same surface and sizing field gave a different mesh on every call, with
 * one thread or many. pytetwild's extension links libstdc++ dynamically and calls
 * std::random_device::_M_getval() through its symbol table. This module defines that
 * symbol. Loaded with RTLD_GLOBAL before pytetwild is imported (see tetwild_process.py),
 * it sits in the global symbol scope, which the dynamic linker searches before
 * pytetwild's own libstdc++: every random_device draw in that process then comes from
 * the generator below, restarted by seed(). Nothing else changes: fTetWild runs the same
 * algorithm from a known seed instead of a hardware one.
 *
 * The generator is SplitMix64 (Steele, Lea & Flood 2014), upper 32 bits per draw.
 * draws() counts the draws since the last seed(): 0 after a mesh means fTetWild did not
 * read random_device through this symbol, and the mesh was not made reproducible.
 *
 * Only the child process that runs fTetWild loads this module (flexcal's meshing child):
 * no other library shares that process.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>

static uint64_t state = 0;
static unsigned long long n_draws = 0;

static uint32_t next_value(void)
{
    uint64_t z = (state += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    z ^= z >> 31;
    return (uint32_t)(z >> 32);
}

/* unsigned int std::random_device::_M_getval() (libstdc++, GLIBCXX_3.4.18); the object
 * pointer is ignored: one stream for every random_device in the process. */
__attribute__((visibility("default"))) unsigned int _ZNSt13random_device9_M_getvalEv(void *self)
{
    (void)self;
    n_draws++;
    return next_value();
}

static PyObject *entropy_seed(PyObject *module, PyObject *arg)
{
    unsigned long long value = PyLong_AsUnsignedLongLong(arg);
    if (value == (unsigned long long)-1 && PyErr_Occurred())
        return NULL;
    state = (uint64_t)value;
    n_draws = 0;
    Py_RETURN_NONE;
}

static PyObject *entropy_draws(PyObject *module, PyObject *unused)
{
    return PyLong_FromUnsignedLongLong(n_draws);
}

static PyMethodDef methods[] = {
    {"seed", entropy_seed, METH_O, "seed(n): restart the random_device stream at n (a non-negative integer)."},
    {"draws", entropy_draws, METH_NOARGS, "draws(): random_device draws served since the last seed()."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_entropy",
    "A fixed std::random_device stream for fTetWild (see fem/_entropy.c).", -1, methods,
};

PyMODINIT_FUNC PyInit__entropy(void)
{
    return PyModule_Create(&module);
}

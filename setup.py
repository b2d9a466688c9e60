"""Build step for the two compiled pieces. Everything else is in pyproject.toml.

- flexcal.fem._entropy (fem/_entropy.c): the fixed entropy source that makes fTetWild's meshes
  repeat. Without it fTetWild runs unseeded, and flexcal warns when it meshes
  (fem/tetwild_process.py).
- flexcal.model._consistent_map (model/_consistent_map.c): the consistent model's map with the
  six chains as vector lanes (model/consistent_native.py). Without it the consistent kernel
  runs numba's scalar copy of the same formulas, 2.6-3.4x slower (docs/model.md 10).

optional=True: without a C compiler the install still succeeds, with the fallbacks above.
"""

from setuptools import Extension, setup

setup(ext_modules=[Extension("flexcal.fem._entropy", sources=["fem/_entropy.c"], optional=True),
                   Extension("flexcal.model._consistent_map", sources=["model/_consistent_map.c"], optional=True)])

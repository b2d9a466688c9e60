"""Build step for the one compiled piece: flexcal.fem._entropy (fem/_entropy.c), the fixed
entropy source that makes fTetWild's meshes repeat. Everything else is in pyproject.toml.

optional=True: without a C compiler the install still succeeds; fTetWild then runs
unseeded, and flexcal warns when it meshes (fem/tetwild_process.py).
"""

from setuptools import Extension, setup

setup(ext_modules=[Extension("flexcal.fem._entropy", sources=["fem/_entropy.c"], optional=True)])

"""Hinge-dimension sweeps, FEM against the closed forms: the design space (`space.py`), one
design point (`job.py`, `identify.py`), the run over a grid or Latin hypercube (`run.py`) and
its table (`table.py`). docs/sweep.md.
"""

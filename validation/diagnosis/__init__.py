"""Sim-to-real gap diagnosis: the calibrated baseline (`baseline.py`), where the residual
lies (`where.py`), which effect explains it (`which.py`), the whole diagnosis
(`diagnose.py`), its blind benchmark (`benchmark.py`) and pictures (`plots.py`).
docs/diagnosis.md.
"""

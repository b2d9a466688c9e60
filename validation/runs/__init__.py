"""Whole runs of the model against data: the Section 3.3 regression (`verify.py`), closed-loop
compensation (`compensate.py`, `targets.py`) and the FEM-corrected model the runs calibrate
(`model_correction.py`, and the chains' measured second-order shortening of the consistent
model, `chain_kinematics.py`). docs/verification-table1.md, docs/compensation.md, docs/model.md 10.
"""

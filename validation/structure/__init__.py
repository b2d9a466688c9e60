"""The mount as a structure on the virtual prototype's reduced model (``flexcal structure``):
mass and modes, support stiffness, buckling factors (`mount.py`), segment masses
(`segment_mass.py`), meshed Guyan-reduced segments with their stress fields
(`fem_segments.py`), leaf stresses by beam theory (`stress.py`) and the report
(`report.py`). docs/structure.md.
"""

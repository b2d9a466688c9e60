"""The virtual prototype (the "truth"): the mount as FEM superelements joined by SE(3)
kinematics (`mechanism.py`, `equilibrium.py`, `superelement.py`, `kinematics.py`), cut into
segments whose stiffness a provider gives (`segments.py`, `fem_provider.py`, `providers.py`),
the ball-screw transmission (`transmission.py`, `fixed_point.py`), scenarios and the
synthetic curves they make (`scenario.py`, `truth.py`). docs/prototype.md.
"""

"""The virtual prototype (the "truth"): the mount as FEM superelements joined by SE(3)
kinematics (`mechanism.py`, `equilibrium.py`, `superelement.py`, `kinematics.py`), cut into
segments whose stiffness a provider gives (`segments.py`, `fem_provider.py`, `providers.py`;
`tied_chains.py`: the option of joining them through section fields at the cuts),
the ball-screw transmission (`transmission.py`, `fixed_point.py`), scenarios and the
synthetic curves they make (`scenario.py`, `truth.py`). docs/prototype.md.
"""

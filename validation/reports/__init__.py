"""Reports: FEM against closed form for a hinge or chain (`fem.py`), model against FEM
(`model_vs_fem.py`), compensation tables (`compensation.py`), plots (`plots.py`) and the
self-contained HTML page of a run folder (`html.py`).
"""

"""Reports: FEM against closed form for a hinge or chain (`fem.py`), model against FEM
(`model_vs_fem.py`), the verify run's report (`verify.py`), compensation tables
(`compensation.py`), the diagnosis benchmark's report.md (`diagnose_benchmark.py`), the
mount's picture and STEP (`mount_view.py`), plots (`plots.py`) and the
self-contained HTML page of a run folder (`html.py`); `safe_markdown.py` escapes strings
from data for report.md (`md_text`, used by every report.md writer) and renders report.md
for the page without any address.
"""

"""Unmodelled effects: the hook the prototype calls (`hooks.py`), the injectors that add an
effect to the prototype (`injectors.py`), the matching model-side terms (`terms.py`), the
size of an effect (`magnitude.py`) and the catalogue by id (`library.py`). docs/effects.md.
"""

"""flexcal.geometry: parametric flexure hinges, chains and the reference mechanism (CadQuery solids load lazily).

Public names load on first use (``flexcal.geometry._lazy``).
"""

from __future__ import annotations

from flexcal.geometry._lazy import lazy_exports

_EXPORTS = {
    "Material": "params",
    "STEEL": "params",
    "CircularNotchHinge": "params",
    "LeafHinge": "params",
    "FlexureChain": "params",
    "ChainSegment": "params",
    "ChainPlacement": "params",
    "MechanismParams": "params",
    "reference_mechanism": "params",
    "chain_rotation": "params",
    "BoxPiece": "exact",
    "LeafPiece": "exact",
    "NotchPiece": "exact",
    "ThinSection": "exact",
    "pieces": "exact",
    "piece_label": "exact",
    "thin_sections": "exact",
    "exact_volume": "exact",
    "end_names": "exact",
    "end_planes": "exact",
    "reference_points": "exact",
    "bounding_box": "exact",
    "PlanePatch": "surfaces",
    "CylinderPatch": "surfaces",
    "Patch": "surfaces",
    "boundary_patches": "surfaces",
    "Part": "solids",
    "hinge_solid": "solids",
    "chain_solid": "solids",
    "segment_solid": "solids",
    "mechanism_assembly": "solids",
    "MIN_FEATURE_SIZE": "solids",
    "export_step": "export",
    "export_stl": "export",
    "import_step": "export",
}

__getattr__, __dir__, __all__ = lazy_exports(__name__, _EXPORTS)

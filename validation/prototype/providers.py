"""The virtual prototype's segment stiffness, chosen by name: ``fem`` (FEM condensation of the
as-built segments on the mapped multi-block mesh, each chain's five segments joined through
section fields at its four cuts, ``tied_chains.DEFAULT_TIES``: the default since session 25;
docs/meshing.md "Session 25: the prototype's cuts tied by default"), ``fem-rigid`` (the same
segments joined rigidly at the cuts, as the prototype was until session 24: the whole chains
19-23 % too stiff axially; for comparison), ``fem-tetwild`` (rigidly joined segments on fTetWild
meshes of the CadQuery solids: the ties need the mapped mesh's faces) or ``analytic`` (the
closed-form compliance; truth then shares the model's hinge formulas, so it is for checks
only). Every FEM provider meshes on the prototype's grid (``PROTOTYPE_CHAIN_OPTIONS``)."""

from __future__ import annotations

__all__ = ["stiffness_provider", "PROVIDERS"]

PROVIDERS = ("fem", "fem-rigid", "fem-tetwild", "analytic")


def stiffness_provider(kind: str, *, progress: bool = True, workers: int | None = 0, scheduler: str | None = None):
    """The segment stiffness provider by name; workers / scheduler: where the FEM
    provider builds missing segments (``fem_provider``; 0 without a scheduler: here, in order)."""
    if kind not in PROVIDERS:
        raise ValueError(f"unknown stiffness provider {kind!r}: use one of {', '.join(PROVIDERS)}")
    if kind == "analytic":
        from .segments import analytic_provider

        return analytic_provider()
    from .fem_provider import fem_provider

    if kind == "fem-tetwild":
        from .fem_provider import TETWILD_ELEMENTS_THROUGH

        return fem_provider(progress=progress, workers=workers, scheduler=scheduler, mesher="tetwild",
                            elements_through_thickness=TETWILD_ELEMENTS_THROUGH)
    if kind == "fem":
        from .tied_chains import DEFAULT_TIES, tied_fem_provider

        return tied_fem_provider(DEFAULT_TIES, progress=progress, workers=workers, scheduler=scheduler)
    return fem_provider(progress=progress, workers=workers, scheduler=scheduler)

"""The version tags of the nonlinear reference that enter cache keys (pure): the hyperelastic solver's
(:data:`SOLVER_VERSION`, :func:`solver_tag`) and the stable-branch sweep's (:data:`UNLOAD_VERSION`). The
served tables' keys carry them (:mod:`flexsheet.fem.snapshots`, :mod:`flexsheet.fem.sphere_snapshots`,
:mod:`flexsheet.fem.path_snapshots`), so the real-time side reads them from here without the solver."""

from __future__ import annotations

from flexsheet.fem.reference.capsule_contact import CONTACT_LAWS, DEFAULT_CONTACT

__all__ = ["SOLVER_VERSION", "UNLOAD_VERSION", "solver_tag"]

#: bump when the reference's formulation or defaults change
#: (cache keys; :mod:`flexsheet.fem.reference.hyperelastic`)
SOLVER_VERSION = "nh-7"
#: version of :func:`flexsheet.fem.reference.path_solver.stable_states`' definition (cache keys of the stable
#: paths and the snapshot tables built from them); bump when it changes
UNLOAD_VERSION = "unload-2"


def solver_tag(contact: str = DEFAULT_CONTACT) -> str:
    """Cache-key tag of the reference solver (:data:`SOLVER_VERSION`) with this contact law (the version, plus
    the law when it is not frictionless, so frictionless solves cached before the option existed stay valid).
    Raises ``ValueError`` on an unknown ``contact``."""
    if contact not in CONTACT_LAWS:
        raise ValueError(f"contact must be one of {CONTACT_LAWS}, got {contact!r}")
    return SOLVER_VERSION if contact == "frictionless" else f"{SOLVER_VERSION}-{contact}"

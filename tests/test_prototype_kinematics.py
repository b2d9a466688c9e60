"""The prototype's own SE(3) step (validation/kinematics.py); the algebra it builds on is
tested in tests/test_geometry_frames.py."""

import numpy as np

from flexcal.validation.prototype import kinematics as kin


def test_orthonormalize_removes_drift():
    t = kin.se3_exp(np.r_[0.1, 0.2, 0.3, 0.4, -0.2, 0.1])
    drifted = t.copy()
    drifted[:3, :3] *= 1 + 1e-9
    fixed = kin.orthonormalize(drifted)
    # a rotation scaled by 1 + 1e-9, orthonormalized: round-off only; rtol=0 (default 1e-5 hid it)
    assert np.allclose(fixed[:3, :3] @ fixed[:3, :3].T, np.eye(3), rtol=0, atol=1e-15)
    assert np.allclose(fixed, t, rtol=0, atol=1e-14)  # as above


"""The prototype's own SE(3) step (validation/kinematics.py); the algebra it builds on is
tested in tests/test_geometry_frames.py."""

import numpy as np

from flexcal.validation import kinematics as kin


def test_orthonormalize_removes_drift():
    t = kin.se3_exp(np.r_[0.1, 0.2, 0.3, 0.4, -0.2, 0.1])
    drifted = t.copy()
    drifted[:3, :3] *= 1 + 1e-9
    fixed = kin.orthonormalize(drifted)
    assert np.allclose(fixed[:3, :3] @ fixed[:3, :3].T, np.eye(3), atol=1e-15)
    assert np.allclose(fixed, t, atol=1e-14)

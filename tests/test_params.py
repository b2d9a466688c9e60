"""Parameter types: validation names the parameter, the value and the allowed range."""

import dataclasses

import numpy as np
import pytest

from flexcal.geometry.params import (CircularNotchHinge, FlexureChain, LeafHinge, MechanismParams,
                                     reference_mechanism)


@pytest.mark.parametrize(
    "build, words",
    [
        (lambda: CircularNotchHinge(radius=5e-3, thickness=0.0, width=10e-3, block_length=5e-3), ["thickness=0", "> 0"]),
        (lambda: CircularNotchHinge(radius=-1e-3, thickness=1e-3, width=10e-3, block_length=5e-3), ["radius=-1", "> 0"]),
        (lambda: LeafHinge(length=20e-3, thickness=4e-3, width=40e-3, fillet=11e-3, block_length=5e-3), ["fillet=11", "<= length/2 = 10"]),
        (lambda: LeafHinge(length=-1e-3, thickness=4e-3, width=40e-3, fillet=0, block_length=5e-3), ["length=-1"]),
        (lambda: FlexureChain(length=0.05), ["length=50", "> 2*end_block"]),
        (lambda: FlexureChain(length=0.2, thickness_1=float("nan")), ["thickness_1", "finite"]),
    ],
)
def test_bad_parameters_raise_value_error_naming_them(build, words):
    with pytest.raises(ValueError) as info:
        build()
    for word in words:
        assert word in str(info.value)


def test_reference_mechanism_geometry():
    mech = reference_mechanism()
    assert [c.name for c in mech.chains] == ["L1", "L2", "L3", "D1", "D2", "D3"]
    for placement in mech.load_chains:
        a, b = np.array(placement.point_a), np.array(placement.point_b)
        # the load-chain axes meet at O_C: B - A is parallel to B - O_C (remote centre)
        cross = np.cross(b - a, b)
        assert np.linalg.norm(cross) < 1e-15  # round-off of ~0.3 m coordinates: measured 7e-18 m^2 (was 1e-12)
    for placement in mech.chains:
        rot = placement.rotation
        # round-off; rtol=0 (default 1e-7 hid it); measured 2.2e-16 (was atol 1e-12)
        np.testing.assert_allclose(rot.T @ rot, np.eye(3), rtol=0, atol=1e-15)
        assert np.linalg.det(rot) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="chains must be"):
        dataclasses.replace(mech, chains=mech.chains[::-1])
    assert isinstance(mech, MechanismParams)

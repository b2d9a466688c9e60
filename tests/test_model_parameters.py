"""The 45 error sources (model/parameters.py): order, bounds, Eq. 9, subsets, the doc table."""

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from flexcal.model.param_file import read_parameter_file
from flexcal.model.parameters import parameter_space, parameter_table_markdown

SPACE = parameter_space()


def test_the_45_sources_in_the_agreed_order():
    names = SPACE.names
    assert len(names) == 45
    assert names[:5] == ("L1.w", "L1.a", "L1.l", "L1.t1", "L1.t2")
    assert names[25:30] == ("D3.w", "D3.a", "D3.l", "D3.t1", "D3.t2")
    assert names[30:36] == ("L1.d", "L1.phi", "L2.d", "L2.phi", "L3.d", "L3.phi")
    assert names[36:] == ("D1.mu", "D1.CL", "D1.x0", "D2.mu", "D2.CL", "D2.x0", "D3.mu", "D3.CL", "D3.x0")


def test_parameters_are_found_by_name():
    names = np.array(SPACE.all_names)
    assert names[SPACE.indices("D*.x0")].tolist() == ["D1.x0", "D2.x0", "D3.x0"]
    assert names[SPACE.indices("L1.*")].tolist() == ["L1.w", "L1.a", "L1.l", "L1.t1", "L1.t2", "L1.d", "L1.phi"]
    table = names[SPACE.chain_indices("mu", "CL", "x0")]  # (chains, symbols)
    assert table.tolist() == [[f"{c}.{s}" for s in ("mu", "CL", "x0")] for c in ("D1", "D2", "D3")]
    assert names[SPACE.chain_indices("w", "t2")].shape == (6, 2)
    assert not SPACE.indices("*.d").flags.writeable  # cached: nobody may change them
    with pytest.raises(ValueError, match="no parameter name matches 'D1.x9'"):
        SPACE.indices("D1.x9")
    with pytest.raises(ValueError, match="same chains"):
        SPACE.chain_indices("d", "mu")  # load chains vs drives


def test_bounds_follow_the_paper():
    p = SPACE.parameter("D1.t1")
    assert p.nominal == pytest.approx(3e-3) and (p.lower, p.upper) == pytest.approx((2.7e-3, 3.3e-3))
    assert (SPACE.parameter("L2.d").lower, SPACE.parameter("L2.d").upper) == (0.0, 2e-3)
    assert SPACE.parameter("L2.phi").upper == pytest.approx(2 * np.pi)
    mu = SPACE.parameter("D3.mu")
    assert (mu.lower, mu.upper, mu.nominal) == (0.75, 1.0, 1.0)
    assert (SPACE.parameter("D1.CL").upper, SPACE.parameter("D2.x0").lower) == (0.5e-3, -0.5e-3)
    assert np.all(SPACE.lower <= SPACE.nominal_vector) and np.all(SPACE.nominal_vector <= SPACE.upper)


@settings(max_examples=30, deadline=None)
@given(eta=arrays(float, (3, 45), elements=st.floats(0, 1)))
def test_eq9_unit_cube_round_trip(eta):
    values = SPACE.from_unit(eta)
    # lo + eta (hi - lo) rounds by ~1 ulp of values up to 2 pi (8.9e-16)
    assert np.all(values >= SPACE.lower - 1e-15) and np.all(values <= SPACE.upper + 1e-15)
    np.testing.assert_allclose(SPACE.to_unit(values), eta, atol=1e-12)  # (P - lo)/(hi - lo) rounding


def test_salib_problem_and_display_units():
    problem = SPACE.as_salib_problem()
    assert problem["num_vars"] == 45 and problem["names"][0] == "L1.w"
    assert problem["bounds"][0] == pytest.approx([0.036, 0.044])
    display = SPACE.as_salib_problem(display_units=True)
    assert display["bounds"][0] == pytest.approx([36.0, 44.0]) and display["bounds"][36] == pytest.approx([0.75, 1.0])


def test_subset_identifies_only_the_named_sources():
    sub = SPACE.subset(["D2.CL", "D1.x0"], fixed={"D1.mu": 0.8})
    assert sub.names == ("D1.x0", "D2.CL")  # kept in space order
    full = sub.full_values(np.array([[1e-4, 2e-4]]))
    assert full.shape == (1, 45)
    assert full[0, SPACE.index("D1.x0")] == 1e-4 and full[0, SPACE.index("D2.CL")] == 2e-4
    assert full[0, SPACE.index("D1.mu")] == 0.8 and full[0, 0] == SPACE.parameter("L1.w").nominal
    np.testing.assert_allclose(sub.from_unit([0.5, 0.5]), [0.0, 0.25e-3])


@pytest.mark.parametrize("overrides, words", [
    ({"D9.CL": 0.1}, ["unknown parameter name 'D9.CL'"]),
    ({"D1.CL": 0.7}, ["D1.CL=0.7 mm", "[0, 0.5] mm"]),
    ({"L1.w": "wide"}, ["L1.w", "not a number"]),
])
def test_build_values_names_bad_entries(overrides, words):
    with pytest.raises(ValueError) as info:
        SPACE.build_values(overrides, display_units=True)
    for word in words:
        assert word in str(info.value)


def test_build_values_in_display_units():
    values = SPACE.build_values({"D1.CL": 0.25, "L3.phi": 1.5, "D2.mu": 0.8}, display_units=True)
    assert values[SPACE.index("D1.CL")] == pytest.approx(0.25e-3)
    assert values[SPACE.index("L3.phi")] == 1.5 and values[SPACE.index("D2.mu")] == 0.8


def test_parameter_files(tmp_path):
    toml = tmp_path / "p.toml"
    toml.write_text('"D1.CL" = 0.25\n"D1.mu" = 0.83\n')
    assert read_parameter_file(toml) == {"D1.CL": 0.25, "D1.mu": 0.83}
    js = tmp_path / "p.json"
    js.write_text('{"parameters": {"L1.d": 1.5}}')
    assert read_parameter_file(js) == {"L1.d": 1.5}
    bad = tmp_path / "bad.json"
    bad.write_text('{"D1": {"CL": 0.2}}')
    with pytest.raises(ValueError, match="not a number"):
        read_parameter_file(bad)


def test_parameter_files_refused_in_one_line_naming_the_file(tmp_path):
    """A Latin-1 file, a NaN value and a file larger than a settings file may be are each
    refused with a ValueError naming the file (the bounded read of geometry.schema)."""
    latin = tmp_path / "latin.toml"
    latin.write_bytes('"D1.CL" = 0.25 # caf\xe9\n'.encode("latin-1"))
    with pytest.raises(ValueError, match=r"latin\.toml: not UTF-8"):
        read_parameter_file(latin)
    nan = tmp_path / "nan.toml"
    nan.write_text('"D1.CL" = nan\n')
    with pytest.raises(ValueError, match=r"nan\.toml: D1\.CL = nan must be a finite number"):
        read_parameter_file(nan)
    big = tmp_path / "big.toml"
    with big.open("wb") as handle:  # sparse: no 4 MiB written
        handle.truncate(5 * 2**20)
    with pytest.raises(ValueError, match=r"big\.toml: .* bytes is more than a parameter file may hold"):
        read_parameter_file(big)


def test_docs_parameter_table_is_current():
    doc = Path(__file__).resolve().parents[1] / "docs" / "parameters.md"
    assert doc.read_text() == parameter_table_markdown(), "regenerate docs/parameters.md with parameter_table_markdown()"

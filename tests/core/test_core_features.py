import numpy as np
import pytest

from hapticsdk.errors import ValidationError
from hapticsdk.perception.features import Feature, FeatureSpace


def space():
    return FeatureSpace((Feature("GS", "N/mm", 0.1, 4.5), Feature("W", "mJ", 1.0, 50.0)))


def test_validate_shapes_and_nan_name_the_feature():
    s = space()
    assert s.validate([1.0, 2.0]).shape == (1, 2)
    with pytest.raises(ValidationError, match="shape"):
        s.validate(np.zeros((3, 3)))
    with pytest.raises(ValidationError) as e:
        s.validate([[1.0, np.nan]])
    assert e.value.field == "features.W"


def test_bounds_check_and_clip():
    s = space()
    with pytest.raises(ValidationError) as e:
        s.validate([[5.0, 2.0]], check_bounds=True)
    assert e.value.field == "features.GS"
    np.testing.assert_allclose(s.clip(np.array([[5.0, 0.0]])), [[4.5, 1.0]])


def test_unit_mapping_roundtrip_and_degenerate_bound():
    s = FeatureSpace((Feature("a", "", 2.0, 2.0), Feature("b", "", -1.0, 3.0)))
    X = np.array([[2.0, 1.0], [2.0, -1.0]])
    U = s.to_unit(X)
    np.testing.assert_allclose(U[:, 0], 0.0)
    np.testing.assert_allclose(s.from_unit(U), X)


def test_union_subset_and_duplicates():
    a = space()
    b = FeatureSpace((Feature("W", "mJ", 0, 1), Feature("P", "(m/s^2)^2", 0, 9)))
    u = a.union(b)
    assert u.names == ("GS", "W", "P")
    assert u["W"].upper == 50.0  # first definition wins
    assert u.subset(["P", "GS"]).names == ("P", "GS")
    with pytest.raises(ValidationError):
        FeatureSpace((Feature("x", "", 0, 1), Feature("x", "", 0, 1)))
    with pytest.raises(ValidationError):
        Feature("y", "", 2, 1)


def test_vector_requires_every_name():
    s = space()
    np.testing.assert_allclose(s.vector({"W": 3, "GS": 1}), [1, 3])
    with pytest.raises(ValidationError, match="missing"):
        s.vector({"GS": 1})
    with pytest.raises(ValidationError, match="unknown"):
        s.vector({"GS": 1, "W": 2, "Q": 3})

"""Darts, links and orbits through the bindings: every index is checked at the boundary."""

from __future__ import annotations

import numpy as np
import pytest

import topomech


@pytest.fixture
def square(two_triangles: tuple) -> topomech.GMap:
    return topomech.GMap.from_mesh(*two_triangles)


def test_alpha_is_an_involution(square: topomech.GMap) -> None:
    for i in range(square.dimension + 1):
        for d in range(square.n_darts):
            assert square.alpha(i, square.alpha(i, d)) == d
    # numpy integers are accepted as indices
    assert square.alpha(np.int64(0), np.int32(1)) == square.alpha(0, 1)


@pytest.mark.parametrize("dart", [-1, -(2**31), 12, 2**32, 2**70])
def test_bad_darts_are_index_errors(square: topomech.GMap, dart: int) -> None:
    with pytest.raises(IndexError, match=r"dart .* is out of range"):
        square.alpha(0, dart)
    with pytest.raises(IndexError, match=r"dart"):
        square.orbit(dart, "<0>")
    with pytest.raises(IndexError, match=r"dart"):
        square.unsew(2, dart)
    with pytest.raises(IndexError, match=r"dart"):
        square.sew(2, 0, dart)


@pytest.mark.parametrize("dim", [-1, 3, 4, 2**64])
def test_bad_dimensions_are_index_errors(square: topomech.GMap, dim: int) -> None:
    with pytest.raises(IndexError, match=r"dimension .* out of range"):
        square.alpha(dim, 0)
    with pytest.raises(IndexError, match=r"dimension"):
        square.unsew(dim, 0)


def test_non_integers_are_type_errors(square: topomech.GMap) -> None:
    with pytest.raises(TypeError, match="dart must be an int"):
        square.alpha(0, 1.0)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="dimension must be an int"):
        square.alpha("0", 1)  # type: ignore[arg-type]


def test_orbits(square: topomech.GMap) -> None:
    face = square.orbit(0, "<0,1>")
    assert face[0] == 0
    assert len(face) == 6
    assert face.dtype == np.int64
    assert len(square.orbit(0, "<>")) == 1
    assert len(square.orbit(0, "<0,1,2>")) == square.n_darts
    with pytest.raises(topomech.TopologyError, match="malformed orbit type"):
        square.orbit(0, "0,1")
    with pytest.raises(topomech.TopologyError, match="out of range"):
        square.orbit(0, "<7>")


def test_unsew_and_sew_back(square: topomech.GMap) -> None:
    inner = next(d for d in range(square.n_darts) if square.alpha(2, d) != d)
    partner = square.alpha(2, inner)
    before = square.cell_counts()
    v0 = square.version
    square.unsew(2, inner)
    assert square.alpha(2, inner) == inner
    assert square.version != v0
    assert square.is_valid()
    after = square.cell_counts()
    assert after["edges"] == before["edges"] + 1
    assert after["components"] == 2
    with pytest.raises(topomech.TopologyError, match="free"):
        square.unsew(2, inner)
    square.sew(2, inner, partner)
    assert square.cell_counts() == before
    assert square.is_valid()


def test_sew_refusal_leaves_the_map_unchanged(square: topomech.GMap) -> None:
    before = square.cell_counts()
    with pytest.raises(topomech.TopologyError):
        square.sew(2, 0, 0)
    assert square.cell_counts() == before
    assert square.violations() == []


def test_repr(square: topomech.GMap) -> None:
    assert repr(square) == "topomech.GMap(dimension=2, darts=12)"
    assert repr(square.core) == "<topomech._core.GMap dimension=2 darts=12>"

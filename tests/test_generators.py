"""`_core.grid` and `_core.box`: the flat layout, and their argument checks."""

from __future__ import annotations

import numpy as np
import pytest

from topomech import _core


def test_grid_layout() -> None:
    points, kinds, offsets, connectivity = _core.grid(2, 1, 2.0, 1.0, "quad")
    assert points.shape == (6, 3)
    assert points.dtype == np.float64
    assert kinds == ["polygon", "polygon"]
    assert offsets.tolist() == [0, 4, 8]
    assert offsets.dtype == np.int64
    assert connectivity.dtype == np.int64
    assert len(connectivity) == 8
    assert points[:, 2].tolist() == [0.0] * 6
    assert points.max(axis=0).tolist() == [2.0, 1.0, 0.0]


def test_box_layout() -> None:
    points, kinds, offsets, _ = _core.box(1, 1, 2, 1.0, 1.0, 4.0, "hexahedron")
    assert kinds == ["hexahedron"] * 2
    assert offsets.tolist() == [0, 8, 16]
    assert points.max(axis=0).tolist() == [1.0, 1.0, 4.0]


def test_defaults() -> None:
    assert _core.grid(1, 1)[1] == ["polygon"]
    assert _core.box(1, 1, 1)[1] == ["hexahedron"]


def test_scene_spellings_of_elements() -> None:
    # the names a scene's `element` takes (tet, hex, tri) give the kernel names' meshes
    for short, long in [("tet", "tetra"), ("hex", "hexahedron")]:
        a, b = _core.box(2, 1, 1, element=short), _core.box(2, 1, 1, element=long)
        assert a[1] == b[1]
        assert (a[3] == b[3]).all()
    a, b = _core.grid(2, 1, element="tri"), _core.grid(2, 1, element="triangle")
    assert a[1] == b[1]
    assert (a[3] == b[3]).all()


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: _core.grid(0, 1), r"nx must be at least 1, got 0"),
        (lambda: _core.grid(1, -3), r"ny must be at least 1, got -3"),
        (lambda: _core.grid(1, 1, 0.0, 1.0), r"sx must be finite and positive, got 0"),
        (lambda: _core.grid(1, 1, 1.0, float("nan")), r"sy must be finite and positive"),
        (lambda: _core.grid(1, 1, element="hexagon"), r"unknown grid element \"hexagon\""),
        (lambda: _core.box(1, 1, 0), r"nz must be at least 1"),
        (lambda: _core.box(1, 1, 1, sz=float("inf")), r"sz must be finite and positive"),
        (lambda: _core.box(1, 1, 1, element="tets"), r"unknown box element \"tets\""),
        (lambda: _core.box(10**6, 10**6, 10**6), r"too many"),
        (lambda: _core.grid(2**40, 2**40), r"too many"),
    ],
)
def test_argument_checks(call: object, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        call()  # type: ignore[operator]

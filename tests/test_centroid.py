"""Centroid, area, perimeter, circularity and flags of thresholded tracer images."""

import numpy as np
import pytest

from rimcl.core.errors import RimclError
from rimcl.imaging.centroid import TracerFlag, flag_names, locate


def test_square_block_known_centroid_area_perimeter():
    counts = np.zeros((9, 12))
    counts[2:5, 4:7] = 500.0  # 3 x 3 block: rows 2..4, columns 4..6
    blob = locate(counts, threshold=100)
    assert blob.col == pytest.approx(5.5, abs=1e-12)  # pixel 5 spans [5, 6)
    assert blob.row == pytest.approx(3.5, abs=1e-12)
    assert blob.area == 9
    # scikit-image measures the boundary through pixel centres: 4 (k - 1) for a k x k block
    assert blob.perimeter == pytest.approx(8.0)
    assert blob.circularity == pytest.approx(64 / (4 * np.pi * 9))
    assert blob.flags == TracerFlag(0)


def test_weights_grey_and_excess_known_values():
    counts = np.zeros((5, 6))
    counts[2, 2] = 300.0
    counts[2, 3] = 200.0
    grey = locate(counts, threshold=100, weights="grey")
    excess = locate(counts, threshold=100, weights="excess")
    assert grey.col == pytest.approx((2.5 * 300 + 3.5 * 200) / 500)
    assert excess.col == pytest.approx((2.5 * 200 + 3.5 * 100) / 300)
    assert grey.row == excess.row == pytest.approx(2.5)


def test_split_image_uses_the_brightest_component_and_flags_it():
    counts = np.zeros((10, 20))
    counts[4:6, 3:5] = 400.0  # 4 pixels, 4 x 300 excess light
    counts[2:7, 12:15] = 200.0  # 15 pixels, 15 x 100 excess light: brighter in total
    blob = locate(counts, threshold=100)
    assert blob.flags & TracerFlag.SPLIT
    assert blob.area == 15
    assert blob.col == pytest.approx(13.5)
    assert blob.row == pytest.approx(4.5)


def test_diagonal_neighbours_are_one_component():
    counts = np.zeros((6, 6))
    counts[1, 1] = counts[2, 2] = counts[3, 3] = 300.0
    blob = locate(counts, threshold=100)
    assert not blob.flags & TracerFlag.SPLIT
    assert blob.area == 3


def test_below_threshold_gives_no_position():
    counts = np.full((7, 7), 100.0)  # equal to the threshold is not above it
    blob = locate(counts, threshold=100)
    assert blob.flags == TracerFlag.BELOW_THRESHOLD
    assert np.isnan(blob.col) and np.isnan(blob.row) and blob.area == 0


def test_touching_the_window_edge_is_flagged():
    counts = np.zeros((8, 8))
    counts[3:5, 0:2] = 600.0
    assert locate(counts, threshold=100).flags & TracerFlag.TOUCHES_EDGE
    counts = np.zeros((8, 8))
    counts[3:5, 3:5] = 600.0
    assert not locate(counts, threshold=100).flags & TracerFlag.TOUCHES_EDGE


def test_flag_names_are_distinct_bits():
    names = flag_names()
    assert len(names) == len(TracerFlag)
    assert all(bit & (bit - 1) == 0 for bit in names)
    assert names[int(TracerFlag.BELOW_THRESHOLD)] == "below_threshold"


def test_unknown_weights_rejected():
    with pytest.raises(RimclError, match="centroid weights"):
        locate(np.zeros((3, 3)), 1, weights="max")

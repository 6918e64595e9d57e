"""fabricfem.studies.fold_crossings: the crossing pairs sorted by cell (same Q2 cell, neighbouring cells, cells
apart) and the seam labels by position, on small hand-made cases whose answers are known by construction."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from fabricfem.studies import fold_crossings
from fabricfem.studies.fold_crossings import PER_CELL, main, pairs_by_cell, stitched_by_position


def test_nodes_closer_than_the_tolerance_share_a_label():
    x = np.array([[0.0, 0, 0], [1e-4, 0, 0], [3e-4, 0, 0], [1.0, 0, 0], [2.0, 0, 0]])
    labels = stitched_by_position(x, tolerance=2.5e-4)
    assert labels[0] == labels[1] == labels[2]                  # a chain 0-1-2 joins even where 0-2 is 3e-4 apart
    assert len({labels[0], labels[3], labels[4]}) == 3


def test_pairs_are_sorted_by_cell():
    """Three cells of PER_CELL triangles each: cells 0 and 1 share node 5 (by label: node 9 of cell 1 is stitched to
    node 5), cell 2 shares nothing."""
    rng = np.random.default_rng(1)
    triangles = np.concatenate([rng.integers(0, 5, (PER_CELL, 3)), rng.integers(6, 10, (PER_CELL, 3)),
                                rng.integers(20, 25, (PER_CELL, 3))])
    triangles[0] = [0, 1, 5]
    triangles[PER_CELL] = [6, 7, 9]
    labels = np.arange(25)
    labels[9] = 5
    pairs = np.array([[0, 1], [0, PER_CELL], [1, PER_CELL + 3], [0, 2 * PER_CELL], [PER_CELL, 2 * PER_CELL + 1]])
    assert pairs_by_cell(pairs, triangles, labels) == {"same_cell": 1, "neighbouring_cells": 2, "cells_apart": 2}


def test_a_folder_without_a_run_is_refused_in_one_line(tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        main([str(tmp_path), "--cells", "0"])
    assert stop.value.code == 2 and "run_dir: no cloth.xdmf" in capsys.readouterr().err


def test_a_segment_removed_for_the_donning_leaves_the_names_and_widths():
    """The pants' feet are removed during the donning: the posed bodies are then the active segments only, and so
    must be the names and the blend widths the skin gap takes (before: a (6, 6) skin against (8, 8) widths, refused)."""
    widths = np.arange(9.0).reshape(3, 3)
    run = SimpleNamespace(body=SimpleNamespace(segments={"thigh": 0, "shank": 1, "foot": 2}),
                          active_segments=lambda c: np.array([True, c > 1.0, True]),
                          contact=SimpleNamespace(widths=widths))
    names, active_widths = fold_crossings._active_segments(run, 0.5)
    assert names == ["thigh", "foot"]
    np.testing.assert_array_equal(active_widths, [[0.0, 2.0], [6.0, 8.0]])
    assert fold_crossings._active_segments(run, 2.0)[0] == ["thigh", "shank", "foot"]

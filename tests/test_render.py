"""fabricfem.render: the colour map is matplotlib's viridis (compared with matplotlib's own), the colour bar's ends
carry its first and last colours, ticks fall on round steps, and a bad camera or zoom is refused by name."""
from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from fabricfem import render


def test_viridis_is_matplotlibs():
    matplotlib = pytest.importorskip("matplotlib")
    np.testing.assert_array_equal(render.viridis(), np.asarray(matplotlib.colormaps["viridis"].colors))


@pytest.mark.parametrize("low, high, ticks, decimals", [
    (0.0, 5.02, [0, 1, 2, 3, 4, 5], 0), (0.0, 2.5, [0, 0.5, 1, 1.5, 2, 2.5], 1),
    (0.0, 37.65, [0, 10, 20, 30], 0), (0.0, 0.012, [0, 0.002, 0.004, 0.006, 0.008, 0.01, 0.012], 3),
    (-1.0, 1.0, [-1, -0.5, 0, 0.5, 1], 1)])
def test_ticks_fall_on_round_steps(low, high, ticks, decimals):
    values, places = render.nice_ticks(low, high)
    np.testing.assert_allclose(values, ticks, atol=1e-12)
    assert places == decimals


def test_colour_bar_ends_and_layout(tmp_path):
    image = np.full((80, 200, 3), 200, dtype=np.uint8)
    path = tmp_path / "bar.png"
    render.save_with_colour_bar(path, image, "a title", (0.0, 2.0), "p [kPa]", secondary=("[mmHg]", 7.5))
    png = np.asarray(Image.open(path).convert("RGB"))
    assert png.shape == (40 + 80 + 130, 200, 3)
    np.testing.assert_array_equal(png[40:120], image)                      # the picture, under the title
    row = png[40 + 80 + 44 + 10]                                            # through the middle of the bar
    x0, x1 = int(0.2 * 200), int(0.8 * 200)
    colours = (255.0 * render.viridis()).astype(np.uint8)
    index = np.round(255.0 * np.arange(x1 - x0) / (x1 - x0 - 1)).astype(int)   # pixel -> entry, ends to ends
    np.testing.assert_array_equal(row[x0 + 1:x1 - 1], colours[index[1:-1]])    # inside the black outline


def test_bad_colour_range_is_refused(tmp_path):
    with pytest.raises(ValueError, match="clim"):
        render.save_with_colour_bar(tmp_path / "x.png", np.zeros((4, 4, 3), np.uint8), "t", (1.0, 1.0), "p")


def test_bad_camera_and_zoom_are_refused():
    square = render.Layer(np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0]]), np.array([[0, 1, 2]]))
    with pytest.raises(ValueError, match="camera"):
        render.render_layers([square], camera="top")
    with pytest.raises(ValueError, match="zoom"):
        render.render_layers([square], zoom=0.0)

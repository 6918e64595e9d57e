"""Off-screen PNG renders of surfaces with VTK alone, and their colour bars drawn with Pillow.

The run's renders (the skin pressure frames of a wear run, a scene's final field) come at the end of a run, on
the clock of the whole command. pyvista's plotting module imports matplotlib and costs about 0.5 s before the
first frame (measured with dolfinx loaded: pyvista 0.13 s, pyvista.plotting with matplotlib 0.35 s); VTK's
rendering modules and Pillow cost about 0.1 s (docs/findings/2026-11-28-render-cost.md). So this module drives
VTK directly (a lookup table, a light kit, the cameras of pyvista's views) and composes the PNG with Pillow: the
picture, a title above it and a horizontal colour bar below it with a second unit's scale.

The colour bar is not VTK's vtkScalarBarActor: it aborts the process (std::bad_alloc in the std::regex of its
tick-label format) once dolfinx is imported, with the VTK 9.x wheels here. The colour map is matplotlib's viridis,
read from matplotlib's own table (`_cm_listed.py`, parsed as data, so that matplotlib is not imported).
Units: whatever the caller's values carry; positions in metres.
"""
from __future__ import annotations

import ast
import importlib.util
import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

CAMERAS = ("xz", "xy", "yz", "iso")
# camera direction (from the focal point towards the camera) and view-up of pyvista's view_xz/xy/yz/isometric
VIEWS = {"xz": ((0.0, -1.0, 0.0), (0.0, 0.0, 1.0)), "xy": ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
         "yz": ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0)), "iso": ((1.0, 1.0, 1.0), (0.0, 0.0, 1.0))}
WINDOW = (1200, 800)            # pixels of the rendered picture


@dataclass
class Layer:
    """One surface of a render: points (n, 3) [m], cells (m, k) (triangles or quadrilaterals); coloured by
    `values` (n,) over `clim` (viridis) or painted `colour` (RGB in [0, 1]); `opacity`; `edges`: its cell edges
    drawn in black; `wireframe`: only its edges; `smooth`: shaded with interpolated point normals."""

    points: np.ndarray
    cells: np.ndarray
    values: np.ndarray | None = None
    clim: tuple[float, float] = (0.0, 1.0)
    colour: tuple[float, float, float] = (0.5, 0.5, 0.5)
    opacity: float = 1.0
    edges: bool = False
    wireframe: bool = False
    smooth: bool = False
    line_width: float = 1.0


@lru_cache(maxsize=1)
def viridis() -> np.ndarray:
    """(256, 3) float RGB in [0, 1] of matplotlib's viridis, read from its table without importing matplotlib
    (matplotlib is imported instead if its table cannot be found)."""
    spec = importlib.util.find_spec("matplotlib")
    folders = list(spec.submodule_search_locations or []) if spec is not None else []
    for folder in folders:
        try:
            text = (Path(folder) / "_cm_listed.py").read_text()
            start = text.index("_viridis_data = ") + len("_viridis_data = ")
            table = np.asarray(ast.literal_eval(text[start:text.index("]]", start) + 2]), dtype=float)
        except (OSError, ValueError, SyntaxError):
            continue
        if table.shape == (256, 3):
            return table
    import matplotlib  # optional heavy package: only when its table file is not where it is expected
    return np.asarray(matplotlib.colormaps["viridis"](np.linspace(0.0, 1.0, 256))[:, :3])


def _vtk() -> tuple[ModuleType, ModuleType, ModuleType, ModuleType, ModuleType]:
    """VTK's modules used here: vtkCommonCore, vtkCommonDataModel, vtkFiltersCore, vtkRenderingCore and
    util.numpy_support (imported on the first render)."""
    import vtkmodules.vtkRenderingOpenGL2  # noqa: F401  heavy, only when a render is made (the OpenGL back end)
    from vtkmodules import vtkCommonCore, vtkCommonDataModel, vtkFiltersCore, vtkRenderingCore  # heavy, as above
    from vtkmodules.util import numpy_support  # heavy, as above
    return vtkCommonCore, vtkCommonDataModel, vtkFiltersCore, vtkRenderingCore, numpy_support


def _polydata(points: np.ndarray, cells: np.ndarray) -> Any:
    """vtkPolyData of a surface: points (n, 3) [m], cells (m, k) into points (all of one kind)."""
    core, data_model, _, _, convert = _vtk()
    cells = np.asarray(cells, dtype=np.int64)
    k = cells.shape[1]
    polys = data_model.vtkCellArray()
    polys.SetData(convert.numpy_to_vtkIdTypeArray(np.arange(0, k * len(cells) + 1, k, dtype=np.int64), deep=True),
                  convert.numpy_to_vtkIdTypeArray(cells.ravel().copy(), deep=True))
    vtk_points = core.vtkPoints()
    vtk_points.SetData(convert.numpy_to_vtk(np.ascontiguousarray(points, dtype=float), deep=True))
    poly = data_model.vtkPolyData()
    poly.SetPoints(vtk_points)
    poly.SetPolys(polys)
    return poly


def _actor(layer: Layer) -> Any:
    """The vtkActor of one layer."""
    core, _, filters, rendering, convert = _vtk()
    poly = _polydata(layer.points, layer.cells)
    mapper = rendering.vtkPolyDataMapper()
    if layer.values is not None:
        poly.GetPointData().SetScalars(convert.numpy_to_vtk(np.asarray(layer.values, dtype=float), deep=True))
        table = core.vtkLookupTable()
        table.SetNumberOfTableValues(256)
        for i, rgb in enumerate(viridis()):
            table.SetTableValue(i, *rgb, 1.0)
        table.SetRange(*layer.clim)
        table.Build()
        mapper.SetLookupTable(table)
        mapper.SetScalarRange(*layer.clim)
        mapper.SetScalarModeToUsePointData()
        mapper.ScalarVisibilityOn()
    else:
        mapper.ScalarVisibilityOff()
    if layer.smooth:
        normals = filters.vtkPolyDataNormals()
        normals.SetInputData(poly)
        normals.SplittingOff()
        mapper.SetInputConnection(normals.GetOutputPort())
    else:
        mapper.SetInputData(poly)
    actor = rendering.vtkActor()
    actor.SetMapper(mapper)
    prop = actor.GetProperty()
    prop.SetColor(*layer.colour)
    prop.SetOpacity(layer.opacity)
    prop.SetLineWidth(layer.line_width)
    if layer.wireframe:
        prop.SetRepresentationToWireframe()
    if layer.edges:
        prop.EdgeVisibilityOn()
        prop.SetEdgeColor(0.0, 0.0, 0.0)
    return actor


def render_layers(layers: list[Layer], camera: str = "iso", zoom: float = 1.0,
                  size: tuple[int, int] = WINDOW) -> np.ndarray:
    """The picture (H, W, 3) uint8 of `layers` on a white background, seen along `camera` (one of CAMERAS: the
    views of pyvista's view_xz/xy/yz/isometric, fitted to the layers) and zoomed by `zoom` (ValueError naming
    camera or zoom)."""
    if camera not in CAMERAS:
        raise ValueError(f"camera must be one of {CAMERAS}, got {camera!r}")
    if not (isinstance(zoom, (int, float)) and math.isfinite(zoom) and zoom > 0.0):
        raise ValueError(f"zoom must be a positive number, got {zoom!r}")
    _, _, _, rendering, convert = _vtk()
    renderer = rendering.vtkRenderer()
    renderer.SetBackground(1.0, 1.0, 1.0)
    for layer in layers:
        renderer.AddActor(_actor(layer))
    rendering.vtkLightKit().AddLightsToRenderer(renderer)
    direction, up = VIEWS[camera]
    view = renderer.GetActiveCamera()
    view.SetFocalPoint(0.0, 0.0, 0.0)
    view.SetPosition(*direction)
    view.SetViewUp(*up)
    renderer.ResetCamera()
    view.Zoom(zoom)
    window = _window()
    window.SetSize(*size)
    window.AddRenderer(renderer)
    try:
        window.Render()
        grab = rendering.vtkWindowToImageFilter()
        grab.SetInput(window)
        grab.ReadFrontBufferOff()
        grab.Update()
        width, height = grab.GetOutput().GetDimensions()[:2]
        pixels = convert.vtk_to_numpy(grab.GetOutput().GetPointData().GetScalars()).reshape(height, width, -1)
    finally:
        window.RemoveRenderer(renderer)
    return np.ascontiguousarray(pixels[::-1, :, :3])


@lru_cache(maxsize=1)
def _window() -> Any:
    """The process's off-screen render window, made at the first render and kept: a new window (an OpenGL
    context) per frame cost 0.13 s a frame, the kept one 0.06 s (docs/findings/2026-11-28-render-cost.md)."""
    window = _vtk()[3].vtkRenderWindow()
    window.SetOffScreenRendering(1)
    window.SetMultiSamples(0)     # software OpenGL here: 4 x multisampling cost 0.1 s a frame of a wear render
    return window


def nice_ticks(low: float, high: float, count: int = 6) -> tuple[np.ndarray, int]:
    """Tick values in [low, high] at a step of 1, 2, 2.5 or 5 x 10^k: the most ticks not above count + 1 (the
    larger step on a tie), and the decimals to print them with (ValueError naming clim unless low < high, finite)."""
    if not (math.isfinite(low) and math.isfinite(high) and low < high):
        raise ValueError(f"clim must be two finite numbers (low, high) with low < high, got {(low, high)!r}")
    raw = (high - low) / max(count - 1, 1)
    power = math.floor(math.log10(raw))
    best: tuple[int, float] | None = None
    for step in sorted(m * 10.0 ** k for m in (1.0, 2.0, 2.5, 5.0) for k in range(power - 1, power + 2)):
        n = math.floor(high / step + 1e-9) - math.ceil(low / step - 1e-9) + 1
        if n <= count + 1 and (best is None or n > best[0] or (n == best[0] and step > best[1])):
            best = (n, step)
    step = best[1]
    ticks = np.arange(math.ceil(low / step - 1e-9), math.floor(high / step + 1e-9) + 1) * step
    mantissa = step / 10.0 ** math.floor(math.log10(step) + 1e-9)
    decimals = max(0, -int(math.floor(math.log10(step) + 1e-9)) + (1 if abs(mantissa - 2.5) < 1e-9 else 0))
    return ticks, decimals


@lru_cache(maxsize=4)
def _font(size: int) -> Any:
    """DejaVu Sans at `size` pixels (matplotlib's copy, else Debian's), else Pillow's built-in font."""
    from PIL import ImageFont  # loaded only when a colour bar is drawn
    spec = importlib.util.find_spec("matplotlib")
    candidates = [Path(folder) / "mpl-data" / "fonts" / "ttf" / "DejaVuSans.ttf"
                  for folder in (spec.submodule_search_locations or [] if spec is not None else [])]
    candidates.append(Path("/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf"))
    for path in candidates:
        if path.exists():
            return ImageFont.truetype(str(path), size)
    return ImageFont.load_default()


def _scale(draw: Any, values: np.ndarray, decimals: int, x_of: Callable[[float], float], y: int, up: bool) -> None:
    """Tick marks at x_of(values) from the bar edge y and their labels above (`up`) or below it."""
    font = _font(13)
    for value in values:
        x = x_of(value)
        draw.line([(x, y), (x, y - 4 if up else y + 4)], fill="black")
        label = f"{value:.{decimals}f}"
        draw.text((x, y - 6 if up else y + 6), label, fill="black", font=font, anchor="md" if up else "ma")


def save_with_colour_bar(path: str | Path, image: np.ndarray, title: str, clim: tuple[float, float], bar_title: str,
                         secondary: tuple[str, float] | None = None) -> None:
    """PNG of a rendered `image` (H, W, 3) under one `title`, with a horizontal viridis colour bar below it over
    `clim`, labelled `bar_title` (the quantity and its unit), and, if `secondary` = (label, factor), a second
    scale above the bar in another unit (value * factor, e.g. ("[mmHg]", 7.50) for kPa)."""
    from PIL import Image, ImageDraw  # loaded only when a colour bar is drawn
    low, high = float(clim[0]), float(clim[1])
    ticks, decimals = nice_ticks(low, high)                       # refuses a bad clim before drawing
    height, width = image.shape[:2]
    above, below = 40, 130                       # pixels for the title and for the colour bar
    canvas = Image.new("RGB", (width, above + height + below), "white")
    canvas.paste(Image.fromarray(np.ascontiguousarray(image[:, :, :3], dtype=np.uint8)), (0, above))
    draw = ImageDraw.Draw(canvas)
    draw.text((12, above // 2), title, fill="black", font=_font(17), anchor="lm")
    x0, x1 = int(0.2 * width), int(0.8 * width)
    top = above + height + 44
    colours = (255.0 * viridis()[np.linspace(0, 255, x1 - x0).round().astype(int)]).astype(np.uint8)
    canvas.paste(Image.fromarray(np.repeat(colours[None], 20, axis=0)), (x0, top))
    draw.rectangle([(x0, top), (x1 - 1, top + 19)], outline="black")

    def x_of(value: float) -> float:
        return x0 + (x1 - 1 - x0) * (value - low) / (high - low)
    _scale(draw, ticks, decimals, x_of, top + 20, up=False)
    draw.text(((x0 + x1) // 2, top + 46), bar_title, fill="black", font=_font(14), anchor="ma")
    if secondary is not None:
        label, factor = secondary
        ticks, decimals = nice_ticks(low * factor, high * factor)
        _scale(draw, ticks, decimals, lambda v: x_of(v / factor), top, up=True)
        draw.text(((x0 + x1) // 2, top - 26), label, fill="black", font=_font(14), anchor="md")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    canvas.save(path)

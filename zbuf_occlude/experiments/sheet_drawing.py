"""The drawing of a contact sheet (:func:`zbuf_occlude.experiments.contact_sheet.contact_sheet`): its panels, their
titles fitted to the panel's width, and the palette PNG.

matplotlib's Agg canvas draws it (no display, no pyplot state); a title too wide for its panel is broken
after its commas, then at its spaces, and what is still too wide is cut in the middle.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.io.owned import OwnedFolder

if TYPE_CHECKING:  # matplotlib is imported when a sheet is drawn
    from matplotlib.figure import Figure

    from zbuf_occlude.geometry.cameras import Camera

__all__ = ["PANEL_INCHES", "POINTS_PER_INCH", "MAX_DRAWN_POINTS", "image_bounds", "draw_sheet", "write_png"]

#: Points (the unit of font sizes) in an inch.
POINTS_PER_INCH = 72.0
#: Side of one panel, inches.
PANEL_INCHES = 2.2
#: Points drawn per panel at most (a seeded subsample beyond it); titles give the full counts.
MAX_DRAWN_POINTS = 8192
#: Marker area, points², small enough that thousands of points stay legible in a small panel.
MARKER_SIZE = 1.0
#: Title font size, points, at least (a print at 300 dpi shows it 25 pixels tall) ...
TITLE_FONT_SIZE = 6.0
#: ... and larger where the dpi asks for it: capital letters at least this tall, pixels, read on a screen.
MIN_TITLE_CAP_PX = 9.0
#: Cap height of DejaVu Sans, matplotlib's default font, as a share of the font size.
CAP_HEIGHT_EM = 0.73
#: A title's font is at most this share of its panel's side: its up to four lines then take at most
#: about a third of the panel, also at a dpi too low for :data:`MIN_TITLE_CAP_PX` (below 68).
MAX_TITLE_PANEL_SHARE = 1 / 12
#: Share of a panel's width a title line may take: the rest keeps it clear of the next panel's ...
TITLE_WIDTH_SHARE = 0.95
#: ... and of a panel with tick labels, which shift its axes, and so its title, off the panel's centre.
TICKED_TITLE_WIDTH_SHARE = 0.8
#: Tick labels of the sensor views, as a share of the title size.
TICK_LABEL_SHARE = 0.8
#: What stands for the middle of a line too long for its panel.
ELLIPSIS = "…"
COLORMAP = "viridis"
#: Colours of the PNG's palette: a colour map and black text need no more, and the file is then
#: about a third of an RGBA one.
PALETTE_COLORS = 256


def image_bounds(width: int, height: int) -> tuple[tuple[float, float], tuple[float, float]]:
    """The image's outer pixel edges (pixel centres at integers: :mod:`zbuf_occlude.geometry.cameras`)."""
    return (-0.5, width - 0.5), (-0.5, height - 0.5)


def draw_sheet(rows: list, fixed: Camera, dpi: int, rng: np.random.Generator) -> Figure:
    from matplotlib.backends.backend_agg import RendererAgg
    from matplotlib.figure import Figure  # the Agg canvas: no display, no pyplot state
    from matplotlib.font_manager import FontProperties

    # constrained layout keeps the titles of several lines inside the figure and off the panel above
    figure = Figure(figsize=(3 * PANEL_INCHES, max(1, len(rows)) * PANEL_INCHES), dpi=dpi, layout="constrained")
    size = _title_size(dpi)
    font, renderer = FontProperties(size=size), RendererAgg(1, 1, dpi)  # measures text in pixels, as Agg draws it

    def measure(text: str) -> float:
        return renderer.get_text_width_height_descent(text, font, ismath=False)[0]

    axes = figure.subplots(max(1, len(rows)), 3, squeeze=False)
    fixed_bounds = image_bounds(fixed.width, fixed.height)
    for row, (ax_fixed, ax_camera, ax_complete) in zip(rows, axes, strict=False):
        _scatter(ax_fixed, row.fixed_view, row.fixed_depth, fixed_bounds, rng, image=True)
        _scatter(ax_camera, row.camera_view, row.camera_depth, row.camera_bounds, rng, image=row.camera_units == "pixels")
        if row.camera_units == "degrees":
            ax_camera.invert_xaxis()  # azimuth grows to the left, as the sensor sees it
            ax_camera.tick_params(labelsize=TICK_LABEL_SHARE * size, length=2, pad=1)
        if row.complete_view is not None:
            _scatter(ax_complete, row.complete_view, fixed.project(row.complete)[1], fixed_bounds, rng, image=True)
        else:
            ax_complete.set_axis_off()
        for k, (ax, title) in enumerate(zip((ax_fixed, ax_camera, ax_complete), row.titles, strict=True)):
            share = TICKED_TITLE_WIDTH_SHARE if k == 1 and row.camera_units == "degrees" else TITLE_WIDTH_SHARE
            ax.set_title(_fit_title(title, share * PANEL_INCHES * dpi, measure, name_first=k == 0), fontsize=size, pad=2)
    return figure


def _title_size(dpi: int) -> float:
    """The titles' font size, points: :data:`TITLE_FONT_SIZE`, or more where its capitals would be
    less than :data:`MIN_TITLE_CAP_PX` pixels tall at ``dpi``; at most :data:`MAX_TITLE_PANEL_SHARE` of a panel."""
    readable = max(TITLE_FONT_SIZE, MIN_TITLE_CAP_PX / CAP_HEIGHT_EM * POINTS_PER_INCH / dpi)
    return min(readable, MAX_TITLE_PANEL_SHARE * PANEL_INCHES * POINTS_PER_INCH)


def _fit_title(title: str, width_px: float, measure: Callable[[str], float], *, name_first: bool = False) -> str:
    """``title`` in lines of at most ``width_px`` pixels (``measure``: a text's width, pixels).

    A line too wide is broken after its commas, then at its spaces (:func:`_wrap`), so that no
    number is cut; with ``name_first`` the first line is a name, kept on one line; whatever is
    still too wide is cut in the middle (:func:`_shorten`), keeping a long name's start and end.
    """
    out = []
    for k, line in enumerate(title.split("\n")):
        pieces = [line] if k == 0 and name_first else _wrap(line, width_px, measure)
        out += [_shorten(piece, width_px, measure) for piece in pieces]
    return "\n".join(out)


def _wrap(line: str, width_px: float, measure: Callable[[str], float]) -> list[str]:
    """``line`` broken after its commas into pieces of at most ``width_px`` pixels, and a piece still wider at its spaces."""
    pieces = []
    for piece in _greedy(line.split(", "), ", ", ",", width_px, measure):
        pieces += _greedy(piece.split(" "), " ", "", width_px, measure) if measure(piece) > width_px else [piece]
    return pieces


def _greedy(words: list[str], sep: str, mark: str, width_px: float, measure: Callable[[str], float]) -> list[str]:
    """``words`` joined by ``sep`` into as few lines of at most ``width_px`` pixels as the words allow;
    a line broken after a word ends in ``mark`` (a comma)."""
    lines, current = [], words[0]
    for i, word in enumerate(words[1:], start=2):
        end = mark if i < len(words) else ""
        if measure(f"{current}{sep}{word}{end}") <= width_px:
            current = f"{current}{sep}{word}"
        else:
            lines.append(current + mark)
            current = word
    return [*lines, current]


def _shorten(line: str, width_px: float, measure: Callable[[str], float]) -> str:
    """``line``, or the most of its start and end with :data:`ELLIPSIS` between them that fits ``width_px``."""
    if measure(line) <= width_px:
        return line
    lo, hi = 0, len(line) - 1  # characters kept: lo fits (an ellipsis alone), hi does not
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if measure(_middle_cut(line, mid)) <= width_px:
            lo = mid
        else:
            hi = mid
    return _middle_cut(line, lo)


def _middle_cut(line: str, keep: int) -> str:
    """``keep`` characters of ``line``, its first ``ceil(keep / 2)`` and last ``floor(keep / 2)``, around :data:`ELLIPSIS`."""
    head = (keep + 1) // 2
    return line[:head] + ELLIPSIS + line[len(line) - (keep - head) :]


def write_png(figure: Figure, out: Path) -> None:
    """The figure as a palette PNG (:data:`PALETTE_COLORS`), written through the output layer
    (:meth:`~zbuf_occlude.io.owned.OwnedFolder.write_bytes` into ``out``'s folder, held for this one
    name: atomic, recorded, and replacing only a sheet a run of ours wrote).

    The figure is drawn on matplotlib's Agg canvas at its own dpi, and its pixels quantised in
    memory: the pixels ``savefig`` would have encoded, with no PNG written and read back.
    """
    import io

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from PIL import Image  # a dependency of matplotlib

    canvas = FigureCanvasAgg(figure)
    canvas.draw()
    palette = Image.fromarray(np.asarray(canvas.buffer_rgba())).convert("RGB").quantize(PALETTE_COLORS)
    buffer = io.BytesIO()
    palette.save(buffer, format="PNG", optimize=True)
    with OwnedFolder(out.parent, files=[out.name], what=f"the file {out.name}") as folder:
        folder.write_bytes(out.name, buffer.getvalue())


def _scatter(
    ax: Any, xy: NDArray[np.float64], colour: NDArray[np.float64], bounds: tuple, rng: np.random.Generator, *, image: bool
) -> None:
    """Points ``xy`` coloured by ``colour`` (near/low: dark) in the limits ``bounds``; image axes point down."""
    if len(xy) > MAX_DRAWN_POINTS:
        keep = rng.choice(len(xy), MAX_DRAWN_POINTS, replace=False)
        xy, colour = xy[keep], colour[keep]
    ax.scatter(xy[:, 0], xy[:, 1], c=colour, s=MARKER_SIZE, cmap=COLORMAP, linewidths=0, rasterized=True)
    ax.set_xlim(*bounds[0])
    ax.set_ylim(*(bounds[1][::-1] if image else bounds[1]))  # row 0 at the top, as in the image
    ax.set_aspect("equal")  # pixels are square; a degree of azimuth is drawn as long as one of elevation
    if image:
        ax.set_xticks([])
        ax.set_yticks([])

"""Top-down floor plans of a scene (matplotlib, no pyplot): obstacles as polygons coloured by material, the TX as a
star.

Used for quick looks (:func:`save_floorplan_png`), under coverage maps and under dtradar_rl's path plots
(:func:`draw_floorplan` draws into any ``Axes`` and returns it). Every material and the TX get one legend entry.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dtradar_data.geometry.occupancy import footprints, occupancy
from dtradar_data.geometry.xml_meshes import base_footprints
from dtradar_data.scenes.model import Prism, SceneSpec

# Colours loosely follow the material's look (Sionna's own palette is for 3-D renders and too dark for a plan view).
MATERIAL_COLOURS: dict[str, str] = {
    "brick": "#a0522d",
    "concrete": "#9e9e9e",
    "wood": "#d2a86e",
    "metal": "#4f6d8f",
    "glass": "#9fd8e8",
    "marble": "#e8e2d0",
    "chipboard": "#9aa05a",  # cardboard boxes; kept apart from wood,
    "plywood": "#c49a5a",
    "plasterboard": "#ecebe4",
    "wet_ground": "#d17b88",  # people
}
FALLBACK_COLOUR = "#888888"
BASE_COLOUR = "#b8a58c"  # an XML scene's buildings: one colour, their materials are the XML's business


def material_colour(material: str) -> str:
    return MATERIAL_COLOURS.get(material, FALLBACK_COLOUR)


def draw_floorplan(ax, spec: SceneSpec, *, with_grid: bool = False, label: bool = False):
    """Draw ``spec`` into ``ax`` in scene metres (equal aspect) and return ``ax``.

    Obstacles (walls included) are filled polygons, lower objects first so that laptops show on their table; objects
    above the robot (a wall-mounted TV) are hatched. ``with_grid`` shades the cells :func:`occupancy` marks blocked
    and draws the cell lines; ``label`` writes object names. Legend entries: one per material, plus "TX".
    """
    seen: set[str] = set()  # materials with a legend entry already
    _draw_base(ax, spec)
    _draw_prisms(ax, spec, seen)
    _draw_boxes(ax, spec, seen, label=label)
    xmin, ymin, xmax, ymax = _extent(spec)
    if with_grid:
        _draw_grid(ax, spec)
    _draw_tx(ax, spec, label="TX")
    ax.set_xlim(xmin, xmax)
    ax.set_ylim(ymin, ymax)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    return ax


def _legend_entry(material: str, seen: set[str]) -> str:
    """The legend label of a patch of ``material``: the material the first time, hidden after (``seen`` updated)."""
    entry = material if material not in seen else "_nolegend_"
    seen.add(material)
    return entry


def _draw_base(ax, spec: SceneSpec) -> None:
    """An XML scene's buildings, as their sections at robot height, in one colour under one legend entry."""
    for i, polygon in enumerate(base_footprints(spec)):
        ax.add_patch(
            _shapely_patch(
                polygon,
                facecolor=BASE_COLOUR,
                edgecolor="black",
                linewidth=0.3,
                alpha=0.9,
                label="_nolegend_" if i else "buildings (XML)",
                zorder=2,
            )
        )


def _draw_prisms(ax, spec: SceneSpec, seen: set[str]) -> None:
    """A city's prisms, lowest first; those under the robot (lots, roads) faint and beneath the buildings."""
    for prism in sorted(spec.prisms, key=lambda p: (p.top_m, p.name)):
        entry = _legend_entry(prism.material, seen)
        flat = prism.top_m < spec.robot_height_m
        ax.add_patch(
            _polygon_patch(
                prism,
                facecolor=material_colour(prism.material),
                edgecolor="black",
                linewidth=0.3,
                alpha=0.35 if flat else 0.9,
                label=entry,
                zorder=1.2 if flat else 2,
            )
        )


def _draw_boxes(ax, spec: SceneSpec, seen: set[str], *, label: bool) -> None:
    """The box objects, stacked by height; those above the robot hatched; names written when ``label``."""
    from matplotlib.patches import Polygon

    for box, corners in footprints(spec):
        above = box.z_m >= spec.robot_height_m
        entry = _legend_entry(box.material, seen)
        ax.add_patch(
            Polygon(
                corners,
                closed=True,
                facecolor=material_colour(box.material),
                edgecolor="black",
                linewidth=0.5,
                alpha=0.55 if above else 0.9,
                hatch="//" if above else None,
                label=entry,
                zorder=2 + box.z_m,
            )
        )
        if label and box.kind != "wall":
            ax.annotate(box.name, (box.x_m, box.y_m), ha="center", va="center", fontsize=5, zorder=10)


def _draw_grid(ax, spec: SceneSpec) -> None:
    """The cells :func:`occupancy` marks blocked, shaded, and the grid's cell lines."""
    g = spec.grid
    gx0, gy0, gx1, gy1 = g.bounds()
    blocked = occupancy(spec)
    ax.imshow(
        np.where(blocked, 1.0, np.nan),
        origin="lower",
        extent=(gx0, gx1, gy0, gy1),
        cmap="Reds",
        vmin=0,
        vmax=2,
        alpha=0.5,
        interpolation="nearest",
        zorder=1.5,
    )
    for x in np.linspace(gx0, gx1, g.nx + 1):
        ax.plot([x, x], [gy0, gy1], color="0.8", linewidth=0.3, zorder=1)
    for y in np.linspace(gy0, gy1, g.ny + 1):
        ax.plot([gx0, gx1], [y, y], color="0.8", linewidth=0.3, zorder=1)


def _draw_tx(ax, spec: SceneSpec, *, label: str) -> None:
    """The transmitters of ``spec`` as gold stars above everything else."""
    txs = np.array([t.position_m for t in spec.transmitters])
    ax.plot(
        txs[:, 0],
        txs[:, 1],
        marker="*",
        markersize=14,
        color="gold",
        markeredgecolor="black",
        linestyle="none",
        label=label,
        zorder=20,
    )


def _polygon_patch(prism: Prism, **kwargs):
    """A filled patch of a prism's footprint, holes left open."""
    return _rings_patch([prism.exterior, *prism.holes], **kwargs)


def _shapely_patch(polygon, **kwargs):
    return _rings_patch([polygon.exterior.coords[:-1], *(h.coords[:-1] for h in polygon.interiors)], **kwargs)


def _rings_patch(rings, **kwargs):
    from matplotlib.patches import PathPatch
    from matplotlib.path import Path as MplPath

    path = MplPath.make_compound_path(*[MplPath(np.array([*r, r[0]]), closed=True) for r in rings])
    return PathPatch(path, **kwargs)


def _extent(spec: SceneSpec) -> tuple[float, float, float, float]:
    """Outer bounds of everything drawn (walls included), with a small margin; for a city quadrant, its grid and
    transmitter (the city's other buildings are clipped away)."""
    if spec.prisms or spec.base is not None:
        gx0, gy0, gx1, gy1 = spec.grid.bounds()
        corners = [np.array([[gx0, gy0], [gx1, gy1]])]
    else:
        corners = [c for _, c in footprints(spec)]
    pts = np.vstack(corners + [np.array([t.position_m[:2] for t in spec.transmitters])])
    pad = 0.02 * float(max(np.ptp(pts[:, 0]), np.ptp(pts[:, 1])))
    return pts[:, 0].min() - pad, pts[:, 1].min() - pad, pts[:, 0].max() + pad, pts[:, 1].max() + pad


def save_floorplan_png(
    spec: SceneSpec, path: str | Path, *, with_grid: bool = True, label: bool = True, dpi: int = 150
) -> Path:
    """Write a labelled floor plan (blocked cells shaded) to ``path`` and return it."""
    # A bare Figure (no pyplot): no global backend switch, nothing left open in interactive sessions.
    from matplotlib.figure import Figure

    xmin, ymin, xmax, ymax = _extent(spec)
    width = 9.0
    fig = Figure(figsize=(width, max(3.0, width * (ymax - ymin) / (xmax - xmin)) + 0.8))
    ax = fig.add_subplot()
    draw_floorplan(ax, spec, with_grid=with_grid, label=label)
    blocked = occupancy(spec)
    ax.set_title(
        f"{spec.name}: {spec.title}  |  grid {spec.grid.nx} x {spec.grid.ny} @ {spec.grid.cell_m} m, "
        f"{int(blocked.sum())} blocked cells",
        fontsize=9,
    )
    return _save(fig, ax, path, dpi)


def save_city_overview_png(
    specs: list[SceneSpec], path: str | Path, *, highlight: str | None = None, dpi: int = 120
) -> Path:
    """One city's overview: every building, lot and road, each quadrant's grid outline and transmitter (paper
    Fig. 6). ``specs`` are the quadrants' specs (they share the city geometry); ``highlight`` names one to emphasise."""
    from matplotlib.figure import Figure

    first = specs[0]
    ground = next(b for b in first.objects if b.kind == "floor")
    hx, hy = ground.width_m / 2, ground.length_m / 2
    width = 8.0
    fig = Figure(figsize=(width + 2.2, width * hy / hx + 0.8))
    ax = fig.add_subplot()
    _draw_city_prisms(ax, first)
    for spec in specs:
        _draw_quadrant(ax, spec, mine=spec.scene == highlight)
        _draw_tx(ax, spec, label="TX" if spec is specs[0] else "_nolegend_")
    ax.set_xlim(-hx, hx)
    ax.set_ylim(-hy, hy)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m] (east)")
    ax.set_ylabel("y [m] (north)")
    ax.set_title(_city_title(first), fontsize=9)
    return _save(fig, ax, path, dpi)


def _draw_city_prisms(ax, spec: SceneSpec) -> None:
    """Every building, lot and road of the city, lowest first, one legend entry per material."""
    seen: set[str] = set()
    for prism in sorted(spec.prisms, key=lambda p: (p.top_m, p.name)):
        ax.add_patch(
            _polygon_patch(
                prism,
                facecolor=material_colour(prism.material),
                edgecolor="black",
                linewidth=0.3,
                alpha=0.9,
                label=_legend_entry(prism.material, seen),
            )
        )


def _draw_quadrant(ax, spec: SceneSpec, *, mine: bool) -> None:
    """A quadrant's grid outline and its name (``q1`` ... in capitals), in red when ``mine``."""
    from matplotlib.patches import Rectangle

    x0, y0, x1, y1 = spec.grid.bounds()
    ax.add_patch(
        Rectangle(
            (x0, y0),
            x1 - x0,
            y1 - y0,
            fill=False,
            edgecolor="red" if mine else "black",
            linewidth=2.0 if mine else 0.8,
            linestyle="-" if mine else "--",
            zorder=5,
        )
    )
    ax.annotate(
        spec.scene.rpartition("-")[2].upper(),
        ((x0 + x1) / 2, (y0 + y1) / 2),
        ha="center",
        va="center",
        fontsize=18,
        color="red" if mine else "black",
        alpha=0.6,
        zorder=6,
    )


def _city_title(spec: SceneSpec) -> str:
    """The overview's title: the city and how many buildings, lots and road surfaces it has."""
    counts = spec.count_by_kind()
    city = spec.provenance.get("city", spec.scene)
    return (
        f"{city}: {counts.get('building', 0)} buildings, {counts.get('parking', 0)} parking lots, "
        f"{counts.get('road', 0)} road surfaces; quadrants and transmitters"
    )


def _save(fig, ax, path: str | Path, dpi: int) -> Path:
    """Put the legend right of ``ax``, lay ``fig`` out and write it to ``path``; returns the path."""
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7, frameon=False)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=dpi)
    return path

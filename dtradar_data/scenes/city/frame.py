"""The local frame of a city twin: lon/lat projected to UTM metres around the centre of the city's box.

Longitude/latitude are projected to the UTM zone given as ``crs`` (pyproj), then the projected centre of the lon/lat
box is subtracted, so x is UTM easting and y UTM northing in metres around the box centre. UTM grid north differs from
true north by the grid convergence (about 1.2 degrees in Dallas and Houston): the lon/lat box is a slightly rotated
quadrilateral in this frame. Features are clipped to the axis-aligned rectangle ``[-hx, hx] x [-hy, hy]`` whose half
sizes are half the projected distances between opposite edge midpoints of the box (:func:`local_extent`); its corners
differ from the box corners by a few metres (about 5.6 m in Dallas).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from pyproj import CRS, Transformer
from pyproj.exceptions import CRSError

from dtradar_data.core.errors import InvalidCoordinatesError, SceneFileError
from dtradar_data.scenes.city.footprints import LonLatBox

__all__ = ["utm_crs_for", "check_crs", "local_transform", "local_extent"]


def utm_crs_for(box: LonLatBox) -> str:
    """The WGS 84 / UTM zone EPSG code of the box centre, e.g. "EPSG:32614" for Dallas."""
    lon, lat = box.centre
    zone = min(int((lon + 180.0) // 6.0) + 1, 60)
    return f"EPSG:{32600 + zone if lat >= 0 else 32700 + zone}"


def check_crs(crs: str, box: LonLatBox) -> CRS:
    try:
        parsed = CRS.from_user_input(crs)
    except CRSError as e:
        raise SceneFileError(
            f"crs {crs!r} is not a coordinate reference system pyproj knows ({e})",
            hint=f"use the UTM zone of the box, here {utm_crs_for(box)}",
        ) from None
    unit = parsed.axis_info[0].unit_name if parsed.axis_info else ""
    if not parsed.is_projected or unit not in ("metre", "meter"):
        raise SceneFileError(
            f"crs {crs!r} is not a projected CRS in metres",
            hint=f"use the UTM zone of the box, here {utm_crs_for(box)}",
        )
    area = parsed.area_of_use
    lon, lat = box.centre
    if area is not None and not (area.west <= lon <= area.east and area.south <= lat <= area.north):
        raise InvalidCoordinatesError(
            f"the box centre (lon {lon:.5f}, lat {lat:.5f}) lies outside the area of use of {crs} ({area.name})",
            hint=f"use the UTM zone of the box, here {utm_crs_for(box)}",
        )
    return parsed


def local_transform(box: LonLatBox, crs: str) -> Callable[[Any, Any], tuple[Any, Any]]:
    """A function (lon, lat) -> (x, y) local metres: project to ``crs``, subtract the projected box centre.

    Takes scalars or numpy arrays (vectorised through pyproj).
    """
    check_crs(crs, box)
    transformer = Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    cx, cy = transformer.transform(*box.centre)

    def to_local(lon: Any, lat: Any) -> tuple[Any, Any]:
        x, y = transformer.transform(lon, lat)
        return x - cx, y - cy

    return to_local


def local_extent(box: LonLatBox, crs: str) -> tuple[float, float]:
    """Half sizes (hx, hy) in metres of the local clip rectangle: half the distances between opposite edge midpoints."""
    to_local = local_transform(box, crs)
    lon_c, lat_c = box.centre
    xs, ys = to_local(np.array([box.west, box.east, lon_c, lon_c]), np.array([lat_c, lat_c, box.south, box.north]))
    hx = math.hypot(xs[1] - xs[0], ys[1] - ys[0]) / 2.0
    hy = math.hypot(xs[3] - xs[2], ys[3] - ys[2]) / 2.0
    return round(hx, 3), round(hy, 3)

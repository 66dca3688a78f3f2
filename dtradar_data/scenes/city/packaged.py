"""The footprint files that ship with the package (``data/`` beside this module), usable as ``"packaged:<name>"``.

Today one file: the Downtown Dallas buildings from Overture Maps / OpenStreetMap (ODbL), with its NOTICE.
"""

from __future__ import annotations

from importlib import resources
from importlib.resources.abc import Traversable

from dtradar_data.core.errors import unknown_name
from dtradar_data.scenes.city.footprints import CityFootprints, LonLatBox
from dtradar_data.scenes.city.geojson import USER_FILE_LICENCE, read_geojson

__all__ = [
    "packaged_path",
    "packaged_files",
    "read_packaged",
    "DALLAS_FILE",
    "DALLAS_NOTICE_FILE",
    "DALLAS_LICENCE",
    "DALLAS_ATTRIBUTION",
    "CITY_DEFAULT_SOURCES",
]

DALLAS_FILE = "dallas_downtown_buildings_overture.geojson"
DALLAS_NOTICE_FILE = "NOTICE_dallas_downtown_buildings_overture.txt"
DALLAS_LICENCE = "ODbL-1.0"
DALLAS_ATTRIBUTION = "(c) OpenStreetMap contributors, Overture Maps Foundation, ODbL"  # wording of the NOTICE
# licence, attribution and a description of each packaged file (keyed by file name)
_PACKAGED: dict[str, tuple[str, str, str]] = {
    DALLAS_FILE: (DALLAS_LICENCE, DALLAS_ATTRIBUTION, f"packaged Overture/OSM file {DALLAS_FILE}"),
}
# Where each city's footprints come from by default: Dallas ships with the package, Houston needs OSM or a user file.
CITY_DEFAULT_SOURCES: dict[str, str] = {"dallas": f"packaged:{DALLAS_FILE}", "houston": "osm"}


def packaged_path(name: str) -> Traversable:
    """A packaged data file, e.g. ``packaged_path(DALLAS_FILE)``."""
    return resources.files("dtradar_data.scenes.city") / "data" / name


def packaged_files() -> list[str]:
    """Names of the packaged footprint files (usable as ``"packaged:<name>"``)."""
    return sorted(
        p.name
        for p in (resources.files("dtradar_data.scenes.city") / "data").iterdir()
        if p.name.endswith((".geojson", ".json"))
    )


def read_packaged(name: str, box: LonLatBox, crs: str) -> CityFootprints:
    """Footprints from the packaged file ``name`` (one of :func:`packaged_files`), with its licence and attribution."""
    if name not in packaged_files():
        raise unknown_name("packaged footprint file", name, packaged_files())
    licence, attribution, description = _PACKAGED.get(name, (USER_FILE_LICENCE, "unknown", f"packaged {name}"))
    with resources.as_file(packaged_path(name)) as path:
        return read_geojson(path, box, crs, source=description, licence=licence, attribution=attribution)

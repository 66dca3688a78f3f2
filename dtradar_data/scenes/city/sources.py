"""Where a city's footprints come from: one entry point, :func:`load_footprints`, that dispatches on the source.

``"packaged:<file name>"`` (:mod:`.packaged`), ``"osm"`` (a download or its cache, :mod:`.osm`), or the path of a
GeoJSON file (:mod:`.geojson`) or an OpenStreetMap XML file (:mod:`.osm`).
"""

from __future__ import annotations

from pathlib import Path

from dtradar_data.core.errors import SceneFileError
from dtradar_data.scenes.city.footprints import CityFootprints, LonLatBox
from dtradar_data.scenes.city.frame import check_crs
from dtradar_data.scenes.city.geojson import read_geojson
from dtradar_data.scenes.city.osm import download_osm, read_osm_xml
from dtradar_data.scenes.city.packaged import packaged_files, read_packaged

__all__ = ["load_footprints"]

_GEOJSON_SUFFIXES = (".geojson", ".json")
_OSM_SUFFIXES = (".osm", ".xml", ".osm.gz", ".osm.bz2", ".xml.gz", ".xml.bz2")


def load_footprints(
    source: str | Path,
    box: LonLatBox,
    crs: str,
    *,
    cache_dir: str | Path | None = None,
    offline: bool | None = None,
    scene: str | None = None,
) -> CityFootprints:
    """Footprints from ``source``: ``"packaged:<file name>"``, ``"osm"`` (download or cache), or a file path.

    ``cache_dir`` (OpenStreetMap downloads) defaults to ``<data root>/osm``; ``offline`` defaults to
    ``$DTRADAR_OFFLINE``; ``scene`` only names the city in error messages.
    """
    check_crs(crs, box)
    text = str(source)
    if isinstance(source, str) and text.startswith("packaged:"):
        return read_packaged(text[len("packaged:") :], box, crs)
    if isinstance(source, str) and text == "osm":
        return download_osm(box, crs, cache_dir, offline=offline, scene=scene)
    path = Path(text).expanduser()
    lower = path.name.lower()
    if not lower.endswith(_GEOJSON_SUFFIXES + _OSM_SUFFIXES):
        raise SceneFileError(
            f"{path}: unsupported footprint file type {path.suffix or '(no extension)'!r}",
            hint="give a GeoJSON file (.geojson/.json, EPSG:4326) or an OpenStreetMap XML file (.osm/.xml), "
            "'osm' to download from OpenStreetMap, or 'packaged:<name>' for one of: " + ", ".join(packaged_files()),
        )
    if not path.is_file():
        raise SceneFileError(
            f"{path}: no such footprint file",
            hint="check the path (make dataset SCENE=<city> OSM=path/to/file.osm or .geojson), "
            "or use 'osm' to download from OpenStreetMap",
        )
    if lower.endswith(_GEOJSON_SUFFIXES):
        return read_geojson(path, box, crs)
    return read_osm_xml(path, box, crs)

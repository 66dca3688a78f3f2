"""OpenStreetMap footprints through osmnx 2.x: local ``.osm`` XML files, and Overpass downloads cached on disk.

A download asks the Overpass API (``osmnx.features_from_bbox``) for ``building=*``, ``amenity=parking`` and
``highway=*`` in the box, writes the raw result as GeoJSON (EPSG:4326, one feature per OSM element, ``@id`` =
"way/123") plus a sidecar JSON with the download time and the Overpass URL, and then reads that GeoJSON back through
the same code as a user's file, so a first call and every later (cached, offline) call give the same footprints and
the same ``retrieved_utc``. Both cache files are written atomically (temporary file in the same folder, then
``os.replace``); the sidecar is written last, so a cache without a sidecar is an interrupted write and is replaced.

Network rules: nothing is contacted when a cache exists (unless ``refresh=True``) or when offline
(``offline=True`` or ``DTRADAR_OFFLINE=1``). The Overpass endpoint is, in this order, the ``overpass_url`` argument,
``$DTRADAR_OVERPASS_URL``, or ``osmnx.settings.overpass_url`` (default https://overpass-api.de/api). Before handing
over to osmnx, one GET of ``<endpoint>/status`` (short timeout) checks that the server answers: an unreachable server
then fails at once with :class:`FootprintsUnavailableError`, instead of osmnx's 60 s back-off pause. While osmnx runs,
its own HTTP cache is off (our GeoJSON cache replaces it, and osmnx would otherwise write ``./cache`` in the working
directory), and the global ``socket.getaddrinfo`` that osmnx patches to pin the server's IP is restored afterwards.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import hashlib
import json
import math
import os
import socket
import sys
import xml.sax
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any
from xml.etree.ElementTree import ParseError

from dtradar_data.core.errors import (
    CorruptDatasetError,
    MissingDependencyError,
    SceneFileError,
)
from dtradar_data.core.files import write_atomic
from dtradar_data.core.layout import data_root
from dtradar_data.scenes.city.footprints import (
    CITY_BOXES,
    CityFootprints,
    FootprintsEmptyError,
    FootprintsUnavailableError,
    LonLatBox,
)
from dtradar_data.scenes.city.geojson import footprints_from_geojson

__all__ = [
    "OSM_TAGS",
    "OSM_LICENCE",
    "OSM_ATTRIBUTION",
    "ENV_OFFLINE",
    "ENV_OVERPASS_URL",
    "DEFAULT_OVERPASS_URL",
    "read_osm_xml",
    "download_osm",
    "default_cache_dir",
    "cache_paths",
    "is_offline",
    "resolve_overpass_url",
    "gdf_to_geojson",
]

OSM_TAGS: dict[str, bool | str] = {"building": True, "amenity": "parking", "highway": True}
OSM_LICENCE = "ODbL-1.0"
OSM_ATTRIBUTION = "(c) OpenStreetMap contributors, ODbL"
ENV_OFFLINE = "DTRADAR_OFFLINE"
ENV_OVERPASS_URL = "DTRADAR_OVERPASS_URL"
DEFAULT_OVERPASS_URL = "https://overpass-api.de/api"  # osmnx 2.x's default
STATUS_TIMEOUT_S = 15.0  # the reachability check: enough for a slow server, short enough to fail fast offline
CACHE_FORMAT = 1


def _import_osmnx() -> Any:
    try:
        import osmnx
    except ImportError as e:
        raise MissingDependencyError(
            f"reading OpenStreetMap data needs osmnx, which is not importable ({e})", hint='pip install "osmnx>=2.0"'
        ) from None
    if int(osmnx.__version__.split(".")[0]) < 2:
        # osmnx 1.x takes bbox as (north, south, east, west): silently wrong boxes, so refuse it
        raise MissingDependencyError(
            f"osmnx {osmnx.__version__} is too old (2.0 or newer is needed)", hint='pip install -U "osmnx>=2.0"'
        )
    return osmnx


def _osmnx_errors() -> tuple[type, type]:
    from osmnx._errors import InsufficientResponseError, ResponseStatusCodeError

    return InsufficientResponseError, ResponseStatusCodeError


# --- conversion -----------------------------------------------------------------------------------------------------


def _json_value(value: Any) -> Any:
    """A GeoDataFrame cell as a JSON value, or None for missing (NaN/None)."""
    if value is None:
        return None
    if isinstance(value, float) and value != value:  # NaN
        return None
    if isinstance(value, (str, bool, int, float)):
        return value
    if hasattr(value, "item"):  # numpy scalar
        return _json_value(value.item())
    if isinstance(value, (list, tuple)):
        return [_json_value(v) for v in value]
    return str(value)


def gdf_to_geojson(gdf: Any, **metadata: Any) -> dict[str, Any]:
    """An osmnx features GeoDataFrame (index ``element``, ``id``) as a GeoJSON FeatureCollection dict.

    Each feature gets ``id`` and property ``@id`` = "way/123" (overpass-turbo's convention) and its non-null tags.
    Features are ordered by element type and numeric id.
    """
    from shapely.geometry import mapping

    columns = [c for c in gdf.columns if c != "geometry"]
    features = []
    for (element, osm_id), row in sorted(gdf.iterrows(), key=lambda item: (str(item[0][0]), int(item[0][1]))):
        sid = f"{element}/{int(osm_id)}"
        props: dict[str, Any] = {"@id": sid}
        for column in columns:
            value = _json_value(row[column])
            if value is not None:
                props[str(column)] = value
        geom = row["geometry"]
        features.append(
            {
                "type": "Feature",
                "id": sid,
                "properties": props,
                "geometry": None if geom is None or geom.is_empty else mapping(geom),
            }
        )
    return {"type": "FeatureCollection", "metadata": metadata, "features": features}


# --- local XML ------------------------------------------------------------------------------------------------------


def read_osm_xml(path: str | Path, box: LonLatBox, crs: str) -> CityFootprints:
    """Footprints from a local OpenStreetMap XML file (``osmnx.features_from_xml``), e.g. an openstreetmap.org
    "Export" or a JOSM / overpass-turbo download. Licence: ODbL (the file is assumed to be OpenStreetMap data)."""
    path = Path(path).expanduser()
    if not path.is_file():
        raise SceneFileError(
            f"{path}: no such OpenStreetMap file",
            hint="check the path (make dataset SCENE=<city> OSM=path/to/file.osm)",
        )
    ox = _import_osmnx()
    insufficient, _ = _osmnx_errors()
    try:
        gdf = ox.features_from_xml(path, tags=OSM_TAGS)
    except insufficient:
        raise FootprintsEmptyError(
            f"{path}: no building, amenity=parking or highway element in the file",
            hint="export the area with those features (openstreetmap.org > Export)",
        ) from None
    except (ParseError, xml.sax.SAXException, UnicodeDecodeError, KeyError, ValueError) as e:
        raise SceneFileError(
            f"{path}: not a readable OpenStreetMap XML file ({type(e).__name__}: {e})",
            hint="give an .osm XML export (openstreetmap.org > Export, JOSM, overpass-turbo "
            "'raw OSM data'), or a GeoJSON file",
        ) from None
    except OSError as e:
        raise SceneFileError(f"{path}: cannot be read ({e})", hint="check the file's permissions") from None
    doc = gdf_to_geojson(gdf, source=str(path))
    return footprints_from_geojson(
        doc, box, crs, source=f"user file {path}", licence=OSM_LICENCE, attribution=OSM_ATTRIBUTION, origin=str(path)
    )


# --- download and cache ---------------------------------------------------------------------------------------------


def is_offline(offline: bool | None = None) -> bool:
    """``offline`` if given, else whether ``$DTRADAR_OFFLINE`` is set to 1/true/yes/on."""
    if offline is not None:
        return bool(offline)
    return os.environ.get(ENV_OFFLINE, "").strip().lower() in ("1", "true", "yes", "on")


def resolve_overpass_url(url: str | None = None) -> str:
    """The Overpass endpoint: ``url``, else ``$DTRADAR_OVERPASS_URL``, else ``osmnx.settings.overpass_url``."""
    if url:
        return url.rstrip("/")
    env = os.environ.get(ENV_OVERPASS_URL, "").strip()
    if env:
        return env.rstrip("/")
    ox = sys.modules.get("osmnx")  # a user who changed the setting has imported osmnx; don't import it just to read it
    return str(getattr(getattr(ox, "settings", None), "overpass_url", DEFAULT_OVERPASS_URL)).rstrip("/")


def default_cache_dir() -> Path:
    """``<data root>/osm`` (``$DTRADAR_DATA_ROOT``, default ``~/.cache/dtradar``)."""
    return data_root() / "osm"


def cache_paths(box: LonLatBox, cache_dir: str | Path) -> tuple[Path, Path]:
    """(GeoJSON, sidecar JSON) paths of the cached download for ``box`` and :data:`OSM_TAGS`."""
    tags = hashlib.sha256(json.dumps(OSM_TAGS, sort_keys=True).encode()).hexdigest()[:8]
    stem = f"overpass_{box.west:.6f}_{box.south:.6f}_{box.east:.6f}_{box.north:.6f}_{tags}"
    return Path(cache_dir) / f"{stem}.geojson", Path(cache_dir) / f"{stem}.meta.json"


def _read_cache(geojson_path: Path, meta_path: Path) -> tuple[dict, dict] | None:
    """(GeoJSON document, sidecar) of a complete cache entry; None when there is none."""
    if not meta_path.is_file():
        return None  # never written, or interrupted before the sidecar: download again
    fix = f"delete {geojson_path} and {meta_path}, or call with refresh=True, to download again"
    try:
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
        raw = geojson_path.read_bytes()
        doc = json.loads(raw)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise CorruptDatasetError(
            f"cached OpenStreetMap download {geojson_path} cannot be read ({e})", hint=fix
        ) from None
    if not isinstance(meta, dict) or meta.get("geojson_sha256") != hashlib.sha256(raw).hexdigest():
        raise CorruptDatasetError(
            f"cached OpenStreetMap download {geojson_path} does not match its sidecar "
            f"{meta_path} (content hash differs)",
            hint=fix,
        )
    return doc, meta


def _footprints_from_cache(doc: dict, meta: dict, geojson_path: Path, box: LonLatBox, crs: str) -> CityFootprints:
    return footprints_from_geojson(
        doc,
        box,
        crs,
        source=f"OpenStreetMap Overpass download ({meta.get('overpass_url', 'unknown server')})",
        licence=OSM_LICENCE,
        attribution=OSM_ATTRIBUTION,
        retrieved_utc=meta.get("retrieved_utc"),
        origin=f"cached OpenStreetMap download {geojson_path}",
    )


def _scene_name(box: LonLatBox, scene: str | None) -> str:
    if scene:
        return scene
    return next((name for name, (b, _) in CITY_BOXES.items() if b == box), "<city>")


def _unavailable(
    box: LonLatBox, cache_dir: Path, url: str, reason: str, scene: str | None
) -> FootprintsUnavailableError:
    name = _scene_name(box, scene)
    return FootprintsUnavailableError(
        f"OpenStreetMap footprints for the box west {box.west} south {box.south} east {box.east} north {box.north} "
        f"are not available: there is no cached download in {cache_dir}, and {reason}",
        hint=(
            f"either (1) download them: this needs an internet connection to an Overpass API server "
            f"(now {url}; point ${ENV_OVERPASS_URL} or osmnx.settings.overpass_url at another one, and unset "
            f"${ENV_OFFLINE}); the download is cached in {cache_dir} for later offline builds; or (2) use a file: "
            f"make dataset SCENE={name} OSM=path/to/{name.strip('<>')}.osm (an OpenStreetMap XML export, e.g. "
            f"openstreetmap.org > Export) or OSM=path/to/{name.strip('<>')}.geojson (EPSG:4326)"
        ),
    )


@contextlib.contextmanager
def _osmnx_settings(ox: Any, **values: Any) -> Iterator[None]:
    """Set osmnx settings for one call and restore them (and osmnx's patch of socket.getaddrinfo) afterwards."""
    saved = {key: getattr(ox.settings, key) for key in values}
    saved_getaddrinfo = socket.getaddrinfo
    try:
        for key, value in values.items():
            setattr(ox.settings, key, value)
        yield
    finally:
        for key, value in saved.items():
            setattr(ox.settings, key, value)
        socket.getaddrinfo = saved_getaddrinfo


def _check_server(url: str, timeout_s: float, requests_kwargs: Mapping[str, Any]) -> tuple[str | None, bool]:
    """(None, whether osmnx's rate limiting can use /status) when the server answers, else (why it does not)."""
    import requests

    try:
        response = requests.get(
            f"{url}/status",
            timeout=min(timeout_s, STATUS_TIMEOUT_S),
            headers={"User-Agent": "dtradar (osmnx)"},
            **requests_kwargs,
        )
    except requests.RequestException as e:
        return f"the Overpass server {url} could not be reached ({type(e).__name__}: {e})", False
    # osmnx reads the 5th line of /status ("2 slots available now.", "Slot available after: ..."); a server without
    # that endpoint would make osmnx sleep 60 s before every request, so rate limiting is turned off for it
    lines = response.text.split("\n") if response.ok else []
    first = lines[4].split(" ")[0] if len(lines) > 4 else ""
    return None, first.isdigit() or first in ("Slot", "Currently")


def download_osm(
    box: LonLatBox,
    crs: str,
    cache_dir: str | Path | None = None,
    *,
    offline: bool | None = None,
    overpass_url: str | None = None,
    timeout_s: float = 180,
    refresh: bool = False,
    scene: str | None = None,
) -> CityFootprints:
    """Footprints of ``box`` from OpenStreetMap: the cached download in ``cache_dir`` if there is one, else a new
    Overpass download (then cached). ``cache_dir`` defaults to ``<data root>/osm``.

    Raises :class:`FootprintsUnavailableError` (and writes nothing) when there is no cache and the server cannot be
    reached or the session is offline; :class:`CorruptDatasetError` for a damaged cache.
    """
    cache_dir = Path(cache_dir).expanduser() if cache_dir is not None else default_cache_dir()
    geojson_path, meta_path = cache_paths(box, cache_dir)
    if not refresh and (cached := _read_cache(geojson_path, meta_path)) is not None:
        return _footprints_from_cache(*cached, geojson_path, box, crs)
    url = resolve_overpass_url(overpass_url)
    if is_offline(offline):
        raise _unavailable(box, cache_dir, url, f"this session is offline (offline=True or {ENV_OFFLINE}=1)", scene)
    ox = _import_osmnx()
    insufficient, status_error = _osmnx_errors()
    import requests

    why, rate_limit = _check_server(url, timeout_s, ox.settings.requests_kwargs)
    if why:
        raise _unavailable(box, cache_dir, url, why, scene)
    # osmnx writes requests_timeout into the query as [timeout:N]; Overpass accepts only a whole number there
    settings = {"overpass_url": url, "use_cache": False, "requests_timeout": max(1, math.ceil(timeout_s))}
    if not rate_limit:
        settings["overpass_rate_limit"] = False
    try:
        with _osmnx_settings(ox, **settings):
            gdf = ox.features_from_bbox(bbox=box.bbox, tags=OSM_TAGS)
    except insufficient as e:
        if "No matching features" not in str(e):  # osmnx's other use of this error: a reply that is not JSON
            raise _unavailable(box, cache_dir, url, f"the download from {url} failed ({e})", scene) from None
        raise FootprintsEmptyError(
            f"the Overpass server {url} returned no building, amenity=parking or highway feature for the box "
            f"west {box.west} south {box.south} east {box.east} north {box.north}",
            hint="check the box (LonLatBox.from_corners takes (lat, lon) pairs)",
        ) from None
    except (requests.RequestException, status_error) as e:
        raise _unavailable(
            box, cache_dir, url, f"the download from {url} failed ({type(e).__name__}: {e})", scene
        ) from None
    retrieved = dt.datetime.now(dt.timezone.utc).replace(microsecond=0).isoformat().replace("+00:00", "Z")
    doc = gdf_to_geojson(
        gdf,
        source="OpenStreetMap via the Overpass API",
        overpass_url=url,
        retrieved_utc=retrieved,
        licence=OSM_LICENCE,
        attribution=OSM_ATTRIBUTION,
    )
    raw = json.dumps(doc, sort_keys=True).encode()
    meta = {
        "format": CACHE_FORMAT,
        "retrieved_utc": retrieved,
        "overpass_url": url,
        "bbox_wsen": list(box.bbox),
        "tags": OSM_TAGS,
        "osmnx_version": ox.__version__,
        "feature_count": len(doc["features"]),
        "licence": OSM_LICENCE,
        "attribution": OSM_ATTRIBUTION,
        "geojson_sha256": hashlib.sha256(raw).hexdigest(),
    }
    cache_dir.mkdir(parents=True, exist_ok=True)
    write_atomic(geojson_path, raw)
    write_atomic(meta_path, json.dumps(meta, indent=2, sort_keys=True).encode())  # last: marks the entry complete
    return _footprints_from_cache(json.loads(raw), meta, geojson_path, box, crs)  # exactly what a cache read sees

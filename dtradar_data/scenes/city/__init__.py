"""City twins: building, parking-lot and road footprints from packaged files, user files or OpenStreetMap.

Modules, each importing only those below it (an import-linter contract in pyproject.toml):

- :mod:`.reader` — city scene files (``dallas.toml``, ``houston.toml``) into one scene per quadrant;
  :mod:`.document` — the shape of a city scene file (pydantic models) and its errors in the file's words;
- :mod:`.sources` — :func:`~.sources.load_footprints`, the one entry point that dispatches on the footprint source;
  :mod:`.streets` — roads between buildings, the transmitter's and the vehicles' places;
- :mod:`.packaged` — the packaged footprint files; :mod:`.osm` — ``.osm`` XML files and OpenStreetMap downloads
  (osmnx, imported only when used), cached on disk;
- :mod:`.geojson` — a GeoJSON document processed into footprints, and the GeoJSON file reader;
- :mod:`.frame` — the local frame (UTM metres around the box centre); :mod:`.tags` — what OSM/Overture properties
  say (kind, height, material, road width);
- :mod:`.footprints` — the internal form (:class:`~.footprints.CityFootprints`), the lon/lat box, the errors.

Package data (the Downtown Dallas footprints and their NOTICE) lives in ``data/``.
"""

"""City twins: building, parking-lot and road footprints from packaged files, user files or OpenStreetMap.

:mod:`dtradar_data.scenes.city.footprints` holds the internal form (:class:`~.footprints.CityFootprints`) and the
GeoJSON reader; :mod:`dtradar_data.scenes.city.osm` reads ``.osm`` XML files and downloads (and caches) OpenStreetMap
data through osmnx. Package data (the Downtown Dallas footprints and their NOTICE) lives in ``data/``.
"""

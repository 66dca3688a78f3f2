"""Sionna RT's bundled example scenes: their names, where their XML lies, and the grid and transmitter each gets.

The scenes ship inside the installed sionna-rt wheel, but only :mod:`dtradar_data.rt` may import Sionna, and naming,
listing or checking a bundled scene (``sionna:munich``, dataset scene ``sionna-munich``) must work without it, even
where it is not installed; so this module finds the files through package metadata and holds the defaults a build of
each scene uses (:data:`SIONNA_DEFAULTS`), for the XML reader (:mod:`dtradar_data.scenes.xml_shapes`) and the scene
loaders (:mod:`dtradar_data.scenes.xml_scene`) alike.
"""

from __future__ import annotations

from importlib import metadata
from pathlib import Path
from typing import Any

from dtradar_data.core.errors import unknown_name
from dtradar_data.core.files import installed_file

SIONNA_PREFIX = "sionna:"
SIONNA_DIST = "sionna-rt"
SIONNA_LICENCE = "Apache-2.0 (sionna-rt; scene geometry from OpenStreetMap, ODbL)"
SIONNA_ATTRIBUTION = "NVIDIA Sionna RT example scenes; building data (c) OpenStreetMap contributors"

#: The five bundled city scenes: a grid over the central streets and a transmitter in the open above one.
#: Chosen from the scenes' building footprints at 1.5 m (see README, "Sionna scenes"): each grid is 400 m x 400 m
#: around the scene's centre at 5 m cells (the street canyon: all of it at 2 m), so it traces in minutes on 2 CPU
#: cores; each TX stands over a street or square, at least 15 m from every building, 20 m above the ground (the
#: paper's city transmitters are at 18-20 m).
SIONNA_DEFAULTS: dict[str, dict[str, Any]] = {
    "simple_street_canyon": {
        "title": "Sionna simple street canyon",
        "description": "Sionna RT's bundled street canyon: six blocks along one street, on a concrete floor.",
        "grid": {"x0_m": -49.0, "y0_m": -29.0, "cell_m": 2.0, "nx": 50, "ny": 30},
        "tx": {"position_m": [-30.0, 0.0, 20.0]},
    },
    "munich": {
        "title": "Sionna Munich (Frauenkirche)",
        "description": "Sionna RT's bundled twin of central Munich around the Frauenkirche and Marienplatz.",
        "grid": {"x0_m": -197.5, "y0_m": -197.5, "cell_m": 5.0, "nx": 80, "ny": 80},
        "tx": {"position_m": [40.0, 90.0, 20.0]},  # in the square north of the Neues Rathaus
    },
    "munich-10tx": {  # Munich's grid with nine more transmitters: see dtradar_data.scenes.placement
        "xml": "munich",
        "title": "Sionna Munich (Frauenkirche), ten transmitters",
        "description": "Sionna RT's bundled twin of central Munich around the Frauenkirche and Marienplatz, "
        "covered as a deployment would cover it: the Munich twin's transmitter and nine more, 20 m above the "
        "streets, placed in two rounds of greedy coverage (dtradar_data.scenes.placement): five where each sees "
        "the most street cells in line of sight that no other sees (200 m range), then four where the ray-traced "
        "twin of the first six left cells without a path.",
        "grid": {"x0_m": -197.5, "y0_m": -197.5, "cell_m": 5.0, "nx": 80, "ny": 80},
        "tx": [
            {"name": "marienplatz-north", "position_m": [40.0, 90.0, 20.0]},  # the Munich twin's own
            # round 1: python -m dtradar_data place sionna:munich --keep --max-sites 6 --range-m 200
            #   --clearance-cells 0 --height-m 20
            {"name": "south-east", "position_m": [102.5, -157.5, 20.0]},
            {"name": "south-west", "position_m": [-67.5, -87.5, 20.0]},
            {"name": "north-east", "position_m": [127.5, 177.5, 20.0]},
            {"name": "south", "position_m": [-37.5, -172.5, 20.0]},
            {"name": "west", "position_m": [-112.5, 42.5, 20.0]},
            # round 2, over the cells the first six's trace left silent (2 859 of 3 069 heard):
            #   python -m dtradar_data place sionna:munich --heard-in <that twin> --max-sites 4 ...
            {"name": "north-west-corner", "position_m": [-192.5, 197.5, 20.0]},
            {"name": "east", "position_m": [187.5, 2.5, 20.0]},
            {"name": "north-west", "position_m": [-157.5, 137.5, 20.0]},
            {"name": "east-south", "position_m": [157.5, -12.5, 20.0]},
        ],
        # ten path buffers of 10^7 would need ~20 GB; a buffer that fills is re-traced in halves (batch-
        # independent tracing), so a smaller one costs time, not paths
        "rt": {"max_num_paths_per_src": 2_000_000},
    },
    "etoile": {
        "title": "Sionna Paris Etoile",
        "description": "Sionna RT's bundled twin of the Place Charles de Gaulle (Arc de Triomphe), Paris.",
        "grid": {"x0_m": -197.5, "y0_m": -197.5, "cell_m": 5.0, "nx": 80, "ny": 80},
        "tx": {"position_m": [-60.0, 0.0, 20.0]},  # on the roundabout, east of the Arc
    },
    "florence": {
        "title": "Sionna Florence",
        "description": "Sionna RT's bundled twin of central Florence.",
        "grid": {"x0_m": -197.5, "y0_m": -197.5, "cell_m": 5.0, "nx": 80, "ny": 80},
        "tx": {"position_m": [-50.0, -30.0, 20.0]},  # in the square south of the cathedral quarter
    },
    "san_francisco": {
        "title": "Sionna San Francisco",
        "description": "Sionna RT's bundled twin of part of San Francisco, buildings on terrain.",
        "grid": {"x0_m": -197.5, "y0_m": -197.5, "cell_m": 5.0, "nx": 80, "ny": 80},
        "tx": {"position_m": [40.0, 40.0, 33.0]},  # a crossing; the terrain there is at 13 m
    },
}


# ------------------------------------------------------------------------------------------- names
def sionna_scene_names() -> list[str]:
    """``["sionna:etoile", ...]``: the bundled scenes a build can name."""
    return [SIONNA_PREFIX + n for n in sorted(SIONNA_DEFAULTS)]


def dataset_scene_name(name: str) -> str:
    """``"sionna:san_francisco"`` -> ``"sionna-san_francisco"``: the dataset grammar has no colon."""
    return name.replace(":", "-")


def sionna_dataset_scenes() -> list[str]:
    return [dataset_scene_name(n) for n in sionna_scene_names()]


def is_sionna_name(scene: str) -> bool:
    """Whether ``scene`` is meant as a bundled Sionna scene (known or not): ``sionna:...`` or ``sionna-...``."""
    return scene.startswith((SIONNA_PREFIX, "sionna-"))


def sionna_key(scene: str) -> str:
    """``"sionna:munich"`` or ``"sionna-munich"`` -> ``"munich"``; :class:`UnknownNameError` with did-you-mean."""
    key = scene.split(":", 1)[1] if scene.startswith(SIONNA_PREFIX) else scene.removeprefix("sionna-")
    if key not in SIONNA_DEFAULTS:
        raise unknown_name("Sionna scene", scene, sionna_scene_names())
    return key


def sionna_xml(key: str) -> Path:
    """The bundled XML of one Sionna scene, found through package metadata (importing sionna is ``rt``'s job); a
    twin of another's geometry (``munich-10tx``) names the scene it is built on (``"xml"``)."""
    key = SIONNA_DEFAULTS.get(key, {}).get("xml", key)
    return installed_file(SIONNA_DIST, f"sionna/rt/scenes/{key}/{key}.xml", f"the scene sionna:{key}")


def sionna_base(key: str) -> str:
    """The bundled scene whose XML ``key`` traces: itself, or the one a twin of it is built on."""
    return SIONNA_DEFAULTS.get(key, {}).get("xml", key)


def sionna_version() -> str:
    """The installed sionna-rt's version, for a bundled scene's ``source``."""
    try:
        return metadata.version(SIONNA_DIST)
    except metadata.PackageNotFoundError:
        return "(not installed)"

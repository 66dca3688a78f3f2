"""What a dataset version is the hash of: everything that determines its files, computed before any tracing, so
building the same thing twice finds the stored version (:func:`build_inputs`, :func:`moving_build_inputs`; the hash
itself is :func:`dtradar_data.store.versions.version_id`).

A city quadrant's overview plot is one of its version's files, so the specs it draws are an input too
(:func:`city_quadrant_specs`, also what the static build draws).
"""

from __future__ import annotations

import dataclasses

from dtradar_data.core.schema import MOVING_SCHEMA_VERSION, MULTI_TX_SCHEMA_VERSION, SCHEMA_VERSION
from dtradar_data.pipeline import differential
from dtradar_data.pipeline.config import BuildConfig
from dtradar_data.pipeline.coverage import COVERAGE_SUBCELLS
from dtradar_data.scenes import build_targets, load_scene_spec
from dtradar_data.store import versions


def build_inputs(spec, config: BuildConfig, *, libraries: dict[str, str] | None = None) -> dict:
    """Everything that determines a dataset version's files; its hash is the version. ``libraries`` (default: the
    installed versions) lets a check recompute the version of a build made elsewhere.

    Besides the scene and the RT settings: whether the per-path table is stored, the coverage map's settings (it is
    one of the version's files), and for a city quadrant the specs its overview plot draws (the other quadrants)."""
    inputs = {
        **versions.build_inputs(spec.to_dict(), config.rt.hashed(), SCHEMA_VERSION, libraries),
        "per_path": config.per_path,
        "coverage": (
            {
                "solver": "sionna.rt.RadioMapSolver",
                "samples_per_tx": config.coverage_samples,
                "cells_per_grid_cell_side": COVERAGE_SUBCELLS,
            }
            if config.coverage_map
            else None
        ),
    }
    if spec.more_tx:  # only then: one-transmitter versions keep their hashes
        inputs["multi_tx_schema_version"] = MULTI_TX_SCHEMA_VERSION
    if spec.prisms and "city" in spec.provenance:
        inputs["city_overview"] = [s.digest() for s in city_quadrant_specs(spec, config)]
    return inputs


def differential_inputs(inputs: dict, parent_version: str, config: BuildConfig) -> dict:
    """A differential build's inputs: its :func:`build_inputs` and what its kept rows come from, the parent version,
    the differential rule and the re-trace radius (the same scene re-traced from another parent is another version)."""
    return {
        **inputs,
        "differential": {"parent": parent_version, "rule": differential.RULE, "radius_m": config.retrace_radius_m},
    }


def moving_build_inputs(moving_scene, config: BuildConfig, *, libraries: dict[str, str] | None = None) -> dict:
    """Everything that determines a moving twin's files; its hash is the version: the moving scene (its base's
    digest, the movers, the step and the number of snapshots), the RT settings, both schema versions, the library
    versions, the per-path table, and the differential rule and radius each snapshot after the first is traced
    with. No coverage map is rendered (the animation is drawn from the table)."""
    return {
        **versions.build_inputs(moving_scene.to_dict(), config.rt.hashed(), SCHEMA_VERSION, libraries),
        "moving_schema_version": MOVING_SCHEMA_VERSION,
        "moving_digest": moving_scene.digest(),
        "per_path": config.per_path,
        "coverage": None,
        "differential": {
            "rule": differential.RULE,
            "radius_m": max(config.retrace_radius_m, moving_scene.base.grid.cell_m),
        },
    }


def city_quadrant_specs(spec, config: BuildConfig) -> list:
    """The blueprint specs of every quadrant of ``spec``'s city (for the overview plot); a pose twin's quadrant
    carries the twin's transmitter."""
    city = spec.provenance["city"]
    specs = [
        load_scene_spec(s, "blueprint", footprints=config.osm, cell_m=config.cell_m)
        for s, _ in build_targets(city, "blueprint")
    ]
    if original_scene(spec) == spec.scene:
        return specs
    return [dataclasses.replace(q, tx=spec.tx) if q.scene == original_scene(spec) else q for q in specs]


def original_scene(spec) -> str:
    """The scene an antenna-pose-error twin was made from; ``spec.scene`` for any other twin."""
    return (spec.provenance.get("tx_pose_error") or {}).get("scene", spec.scene)

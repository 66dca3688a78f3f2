"""The search for a differential build's parent: the stored blueprint whose rows a dynamic twin may keep
(``--differential``: :mod:`.differential` re-traces only the cells the changed objects can affect).

A parent is used only when every input its kept rows depend on equals this build's; else the build is refused
before anything is traced, naming what differs in the closest stored blueprint. The search reads ``meta.json``
files only.
"""

from __future__ import annotations

import dataclasses

from dtradar_data.core.errors import CorruptDatasetError, DatasetNotFoundError, InvalidSettingError
from dtradar_data.core.ids import DatasetId
from dtradar_data.core.layout import PATHS_FILE, data_root, refs_path, version_dir
from dtradar_data.core.schema import SCHEMA_VERSION
from dtradar_data.pipeline import differential
from dtradar_data.pipeline.config import BuildConfig, scene_config
from dtradar_data.scenes.model import Box
from dtradar_data.store import local, versions


def differential_parent(spec, config: BuildConfig):
    """The stored blueprint a differential build of ``spec`` starts from (with its per-path table when
    ``config.per_path``), and its scene: see :func:`differential_parent_version`."""
    version = differential_parent_version(spec, config)
    parent = local.load(f"{spec.scene}/blueprint", revision=version, paths=config.per_path)
    recorded = parent.meta["scene_spec"]
    parent_spec = dataclasses.replace(spec, variant="blueprint", objects=tuple(Box(**o) for o in recorded["objects"]))
    return parent, parent_spec


def differential_parent_version(spec, config: BuildConfig) -> str:
    """The newest stored blueprint of ``spec``'s scene whose rows a differential build may keep: every input they
    depend on equals this build's (the scene but its objects, every hashed RT setting, the schema and library
    versions, the per-path table: :func:`differential.inherited_differences`), even if a newer one was built with
    other settings. Otherwise :class:`InvalidSettingError` naming what differs in the closest stored blueprint (the
    fewest differences; the newest of equals), before anything is traced; reads ``meta.json`` files only."""
    config = scene_config(config, spec)
    name = f"{spec.scene}/blueprint"
    how = (
        f"build {name} with this build's settings first (`python -m dtradar_data build --scene <the same scene> "
        "--variant blueprint` with the same --rt.* and scene flags; `--variant all --differential` does both), or "
        "drop --differential to trace the dynamic twin in full"
    )
    did = DatasetId(spec.scene, "blueprint", None)
    if not local.local_versions(did):  # a user's scene is not a known name: no "did you mean" another scene
        raise DatasetNotFoundError(
            f"--differential starts from a stored {name}, and none is in {data_root()}", hint=how
        )
    _, newest, _ = local.resolve(did)
    here = spec.to_dict()
    rt = config.rt.hashed()
    libraries = versions.library_versions()
    candidates = [newest] + [v for v in reversed(local.local_versions(did)) if v != newest]
    closest: tuple[str, list[str]] | None = None
    for version in candidates:
        vdir = version_dir(did.scene, did.variant, version)
        try:
            meta = local.read_meta(vdir)
        except CorruptDatasetError:
            if version == newest:
                raise
            continue
        differs = differential.inherited_differences(
            meta,
            here,
            rt,
            schema_version=SCHEMA_VERSION,
            libraries=libraries,
            per_path=config.per_path,
            parent_has_paths=(vdir / PATHS_FILE).is_file(),
        )
        if not differs:
            return version
        if closest is None or len(differs) < len(closest[1]):
            closest = (version, differs)
    assert closest is not None  # the newest one's meta.json was read, or its error raised
    version, differs = closest
    tag = versions.read_refs(refs_path(did.scene, did.variant)).tag_of(version)
    which = "the only one" if len(candidates) == 1 else "the newest" if version == newest else "the closest"
    raise InvalidSettingError(
        f"--differential: no stored {name} was built with the inputs whose rows {spec.name} would keep; "
        f"{which} of {len(candidates)}, {name}@{tag or version} ({version}), differs in: {'; '.join(differs)}",
        hint=how,
    )

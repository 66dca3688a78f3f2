"""The scene a dataset version stores beside its tables: the Mitsuba XML the tracer loaded and every mesh it names,
in one folder that plain Sionna opens (``sionna.rt.load_scene("<version>/scene/scene.xml")``).

The tracer's own XML (:func:`~.meshes.write_mitsuba_scene`) names the spec's meshes by relative paths, but a spec
built on an external XML (Sionna's Munich, a user's file) names that scene's meshes by absolute paths on this
machine. :func:`write_stored_scene` copies those meshes into the folder (``base/<path in the external scene>``) and
rewrites the names, so the folder travels: every byte of it follows from the spec (and, for an external scene, from
the files whose sha256 the spec records), which is what the version hashes.
"""

from __future__ import annotations

import shutil
import xml.etree.ElementTree as ET
from pathlib import Path, PurePosixPath

from dtradar_data.core.layout import SCENE_DIR
from dtradar_data.geometry.meshes import write_mitsuba_scene

#: Where an external scene's meshes go inside the stored folder (apart from the spec's own ``meshes/<material>.ply``).
BASE_DIR = "base"


def write_stored_scene(spec, out_dir: Path) -> dict[str, Path]:
    """Write the scene ``spec`` is traced from into ``out_dir`` (``scene.xml``, ``meshes/*.ply`` and, for a spec on
    an external XML, ``base/...``), self-contained; returns ``{"scene/<path>": file}`` for every file written, the
    names a version lists them under."""
    out_dir = Path(out_dir)
    xml = write_mitsuba_scene(spec, out_dir)
    if spec.base is not None:
        _localise_meshes(xml, Path(spec.base.path).parent, out_dir)
    files = sorted(p for p in out_dir.rglob("*") if p.is_file())
    return {f"{SCENE_DIR}/{p.relative_to(out_dir).as_posix()}": p for p in files}


def _localise_meshes(xml: Path, base_dir: Path, out_dir: Path) -> None:
    """Copy every mesh the XML names by an absolute path into ``out_dir/base/`` and name it there instead (its path
    relative to the external scene's folder, or ``base/extern/<i>-<name>`` for a file outside that folder)."""
    # keep the comments: the one merged_scene_xml writes names the external scene and its sha256
    root = ET.parse(xml, parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))).getroot()
    base_dir = base_dir.resolve()
    for i, el in enumerate(s for shape in root.iter("shape") for s in shape.findall("string")):
        value = el.get("value", "")
        if el.get("name") != "filename" or not Path(value).is_absolute():
            continue
        src = Path(value)
        try:
            rel = PurePosixPath(BASE_DIR, src.relative_to(base_dir).as_posix())
        except ValueError:  # a mesh outside the external scene's folder
            rel = PurePosixPath(BASE_DIR, "extern", f"{i}-{src.name}")
        dest = out_dir / rel
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(src, dest)
        el.set("value", rel.as_posix())
    xml.write_text(ET.tostring(root, encoding="unicode") + "\n", encoding="utf-8")

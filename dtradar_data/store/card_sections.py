"""The dataset card's sections on what only some twins have (a moving twin's snapshots, an antenna-pose-error twin,
a city quadrant), and how the card writes a value: split from :mod:`dtradar_data.store.card`, which renders them."""

from __future__ import annotations

from typing import Any

from dtradar_data.core import layout as P
from dtradar_data.core.record import VersionRecord

MOVING_ROWS = 40


def fmt(value: Any) -> str:
    if value is None:
        return "—"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, (list, tuple)):
        return "(" + ", ".join(fmt(v) for v in value) + ")"
    if isinstance(value, dict):
        return ", ".join(f"{k}={fmt(v)}" for k, v in sorted(value.items()))
    return str(value).replace("|", "\\|").replace("\n", " ")


def moving_section(rec: VersionRecord) -> dict[str, Any] | None:
    """What the card says about a moving twin (``meta["moving"]`` and the builder's ``meta["moving_build"]``)."""
    extra = rec.model_extra or {}
    moving = extra.get("moving")
    if not isinstance(moving, dict):
        return None
    build = extra.get("moving_build") or {}
    movers = []
    for m in build.get("movers") or []:
        movers.append(
            {
                "name": m.get("name"),
                "kind": m.get("kind"),
                "material": m.get("material"),
                "speed": fmt(m.get("speed_mps")),
                "mode": m.get("mode"),
                "waypoints": len(m.get("waypoints") or []),
                "size": f"{fmt(m.get('width_m'))} × {fmt(m.get('length_m'))} × {fmt(m.get('height_m'))}",
                "offset": fmt(m.get("start_offset_s")),
            }
        )
    rows = build.get("per_snapshot") or []
    provenance = build.get("provenance") or {}
    grid = rec.grid
    return {
        "snapshots": moving.get("snapshots"),
        "dt_s": fmt(moving.get("dt_s")),
        "horizon_s": fmt(build.get("horizon_s")),
        "names": ", ".join(f"`{n}`" for n in moving.get("movers") or []),
        "movers": movers,
        "base": (build.get("base") or {}).get("variant", "blueprint"),
        "base_digest": str((build.get("base") or {}).get("digest", ""))[:16],
        "dt_from": provenance.get("dt_from", "—"),
        "horizon_from": provenance.get("horizon_from", "—"),
        "rule": build.get("rule", "—"),
        "radius_m": fmt(build.get("radius_m")),
        "full_seconds": fmt(build.get("full_seconds")),
        "diff_seconds": fmt(build.get("differential_seconds_mean")),
        "retraced_mean": fmt(build.get("retraced_cells_mean")),
        "free_mean": fmt(build.get("free_cells_mean")),
        "full_cells": rows[0].get("retraced_cells", "—") if rows else "—",
        "rows": [
            {
                "t": r.get("t"),
                "mode": r.get("mode"),
                "retraced": r.get("retraced_cells"),
                "free": r.get("free_cells"),
                "moved": ", ".join(r.get("movers_moved") or []) or "—",
                "seconds": fmt(r.get("seconds")),
            }
            for r in rows[:MOVING_ROWS]
        ],
        "rows_left": max(0, len(rows) - MOVING_ROWS),
        "cells_per_snapshot": int(grid.get("nx", 0)) * int(grid.get("ny", 0)),
        "gif": P.MOVING_GIF_FILE if P.MOVING_GIF_FILE in rec.files else None,
    }


def tx_pose_section(rec: VersionRecord) -> dict[str, Any] | None:
    """What the card says about an antenna-pose-error twin (``meta["tx_pose_error"]``), numbers rounded for reading."""
    pose = (rec.model_extra or {}).get("tx_pose_error")
    if not pose:
        return None

    def side(d: dict[str, Any]) -> dict[str, str]:
        return {
            k: "(" + ", ".join(f"{round(float(x), 3) + 0.0:g}" for x in v) + ")" if v else "none" for k, v in d.items()
        }

    return {
        **pose,
        "move_azimuth": f"{float(pose.get('move_azimuth_deg', 0.0)):.1f}",
        "original": side(pose.get("original") or {}),
        "perturbed": side(pose.get("perturbed") or {}),
    }


_PLURALS = {"building": "buildings", "parking": "parking lots", "road": "roads"}


def city_section(rec: VersionRecord) -> dict[str, Any] | None:
    """What the card says about a city quadrant (``meta["city"]``, written by the pipeline from the scene)."""
    city = (rec.model_extra or {}).get("city")
    if not city or "quadrant" not in city:  # an XML scene's provenance (its file) is not a city quadrant's
        return None
    fp, tx, dyn = city.get("footprints", {}), city.get("tx", {}), city.get("dynamic")
    report = fp.get("report") or {}
    skipped = report.get("skipped") or {}
    dynamic = None
    if dyn:
        roads = "; ".join(f"{r['name']} from {r['from_m']} to {r['to_m']}" for r in dyn.get("roads", []))
        vehicles = ", ".join(
            f"{n} {k}{'es' if k == 'bus' and n != 1 else 's' if n != 1 else ''}"
            for k, n in (dyn.get("vehicles") or {}).items()
        )
        dynamic = (
            f"{vehicles} placed with seed {dyn.get('seed')} on {len(dyn.get('roads', []))} roads "
            f"({dyn.get('roads_from')}): {roads}"
        )
    return {
        "city": city.get("city"),
        "quadrant": city.get("quadrant", ""),
        "crs": fp.get("crs"),
        "rect": ", ".join(fmt(v) for v in city.get("quadrant_rect_m", [])),
        "box": fmt(fp.get("box", {})),
        "source": fp.get("source"),
        "retrieved_utc": fp.get("retrieved_utc"),
        "content_hash": str(fp.get("content_hash", ""))[:16],
        "counts": ", ".join(f"{n} {_PLURALS.get(k, k) if n != 1 else k}" for k, n in (fp.get("counts") or {}).items()),
        "report": "; ".join(
            f"{k} {fmt(v)}"
            for k, v in sorted(report.items())
            if k not in ("skipped", "skipped_ids") and v not in ({}, [], None)
        )
        + (f"; skipped {fmt(skipped)}" if skipped else ""),
        "tx_paper": tx.get("paper_m"),
        "tx_placed": tx.get("placed_m"),
        "tx_moved": tx.get("moved_m", 0),
        "clearance": tx.get("clearance_m"),
        "dynamic": dynamic,
    }

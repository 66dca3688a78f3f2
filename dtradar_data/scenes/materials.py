"""The ITU-R P.2040 radio materials that Sionna RT knows, and the frequencies at which each is defined."""

from __future__ import annotations

# Every ITU-R P.2040 material Sionna RT 2.x knows (sionna/rt/radio_materials/itu.py). Not all are defined at
# every frequency: see ITU_VALID_GHZ and material_valid_at().
ITU_VALID_GHZ: dict[str, tuple[float, float]] = {
    "vacuum": (0.001, 100.0),
    "concrete": (1.0, 100.0),
    "brick": (1.0, 40.0),
    "plasterboard": (1.0, 100.0),
    "wood": (0.001, 100.0),
    "glass": (0.1, 100.0),
    "clear_acrylic": (110.0, 330.0),
    "ceiling_board": (1.0, 100.0),
    "chipboard": (1.0, 100.0),
    "plywood": (1.0, 40.0),
    "marble": (1.0, 60.0),
    "floorboard": (50.0, 100.0),
    "vinyl_tile": (1.0, 40.0),
    "carpet_tile": (1.0, 40.0),
    "asphalt_concrete": (1.0, 40.0),
    "metal": (1.0, 100.0),
    "very_dry_ground": (1.0, 10.0),
    "medium_dry_ground": (1.0, 10.0),
    "wet_ground": (1.0, 10.0),
}
ITU_MATERIALS: tuple[str, ...] = tuple(ITU_VALID_GHZ)


def material_valid_at(material: str, frequency_hz: float) -> bool:
    """Whether ITU-R P.2040 (and so Sionna) defines ``material`` at ``frequency_hz``."""
    lo, hi = ITU_VALID_GHZ[material]
    return lo <= frequency_hz / 1e9 <= hi

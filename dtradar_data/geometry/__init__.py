"""Geometry of a scene: triangle meshes and the Mitsuba/Sionna scene file (:mod:`.meshes`), the robot's occupancy
grid and free regions (:mod:`.occupancy`), top-down floor plans (:mod:`.floorplan`). No Sionna here."""

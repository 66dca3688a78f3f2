"""Geometry of a scene: triangle meshes and the Mitsuba/Sionna scene file (:mod:`.meshes`), the shapes of a scene
built on an external XML file as meshes, its ground and footprints (:mod:`.xml_meshes`), the robot's occupancy grid
and free regions (:mod:`.occupancy`), top-down floor plans (:mod:`.floorplan`). No Sionna here."""

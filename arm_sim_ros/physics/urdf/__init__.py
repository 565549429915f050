"""URDF in and out: a planar 2R arm read from URDF into a scene, and a scene's arm written
as URDF. May import: physics.model, scene."""

"""Pictures of runs (matplotlib PNG); a thin layer over the physics core."""

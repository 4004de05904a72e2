"""mpmdem: partitioned MPM-DEM coupler (scene -> backend -> result tables -> metrics -> report)."""
__version__ = "0.1.0"

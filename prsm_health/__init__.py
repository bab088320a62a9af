"""prsm_health: health monitoring of a planetary roller screw actuator (PRSM)."""

__version__ = "0.1.0"

"""Truth simulator: scene files, the actuator's motion, loads, faults, sensors (docs/scenes.md)."""

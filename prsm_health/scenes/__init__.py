"""Truth simulator: scene files, the actuator's motion, loads, faults and sensors (docs/scenes.md)."""

"""Stress suite: filter soak, physics properties, fuzzing (docs/stability.md)."""

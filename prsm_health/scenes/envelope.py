"""Scenes beyond the downhole cycle the estimator's settings were chosen on: the envelope.

Each is a bundled scene with one thing changed (:func:`~prsm_health.scenes.scene.varied_scene`):
the speed, the traction or the wall's load, the drive train, the screw, the drive's sensors or
sample rate, or the motion itself (a ramp, an assisting load, sine strokes that reverse
without stopping). ``prsm-health bench
--scenes envelope`` runs them in the default configuration (those of :data:`MODEL_SETTINGS`
with their settings), told the count too where they have jams, and reports them apart from
the floors, which are the downhole scenes'
(docs/performance.md, "Motion and loads beyond the downhole scenes").
"""

from __future__ import annotations

from typing import Any

from prsm_health.scenes.scene import Scene, varied_scene

#: The sine strokes: 300 rpm either way, a 4 s period, a load of 20 kN that resists the motion.
SINE_PROFILE = {
    "type": "sine",
    "speed_amplitude_rpm": 300.0,
    "speed_offset_rpm": 0.0,
    "period_s": 4.0,
    "axial_load_n": 20000.0,
}
#: A load ramp at a rising speed, over the whole of a 30 s run.
_RAMP = {
    "type": "ramp",
    "speed_start_rpm": 100.0,
    "speed_end_rpm": 600.0,
    "axial_load_start_n": 10000.0,
    "axial_load_end_n": 45000.0,
    "ramp_s": 30.0,
}
#: A load that pushes the way the screw moves (back-driving) at a constant 300 rpm.
_ASSIST = {
    "type": "ramp",
    "speed_start_rpm": 300.0,
    "speed_end_rpm": 300.0,
    "axial_load_start_n": -20000.0,
    "axial_load_end_n": -30000.0,
    "ramp_s": 20.0,
}
_RAMP_JAMS = [{"time_s": 12.0, "roller": 3}, {"time_s": 22.0, "roller": 7}]
_ASSIST_JAM = [{"time_s": 8.0, "roller": 3}]
_SINE_JAM = [{"time_s": 10.3, "roller": 3}]
#: The sine strokes with a load that keeps its sign through the reversals (as gravity).
_GRAVITY = {"axial_load_n": 10000.0, "resisting": False}
#: The screw of papers 001/004: a larger lead, so a jammed roller is a smaller share of the
#: torque (docs/estimation.md, "Another screw").
OTHER_SCREW = "meng2022-misalignment"


#: The estimator's settings for a load released faster than the scenes' 0.5 s (docs/
#: estimation.md, "A load released fast"): off by default, so the envelope shows both.
RELEASE_SETTINGS = {
    "load_transition_acceleration_rad_s2": 200.0,
    "load_jerk_psd_transition_n2_per_s5": 5.0e13,
}
#: The envelope's scenes that run with ``model:`` settings other than the bundled ones
#: (scene name: settings; ``prsm-health bench`` applies them over its parameters).
MODEL_SETTINGS: dict[str, dict[str, float]] = {
    "nominal-release-0.2s-set": RELEASE_SETTINGS,
    "sudden-jam-release-0.2s-set": RELEASE_SETTINGS,
}


def _cycle(**changes: float) -> dict[str, Any]:
    """The bundled scene's downhole cycle with ``changes`` (merged by scene.varied_scene)."""
    return {"type": "downhole_cycle"} | changes


def _drive_train(*, gear_ratio: float, torque_constant_nm_per_a: float) -> dict[str, Any]:
    """Another drive train in the actuator, with the current limit that lets it reach the
    downhole loads (60 A)."""
    drive = {"gear_ratio": gear_ratio, "torque_constant_nm_per_a": torque_constant_nm_per_a}
    return {"actuator": {"drive_train": drive | {"max_current_a": 60.0}}}


#: The downhole cycle with its load released in 0.2 s at each stroke end (the scenes: 0.5 s).
_FAST_RELEASE = _cycle(load_ramp_s=0.2)

_Entry = tuple[str, str, str, dict[str, Any]]


def _with_and_without_jams(
    names: tuple[str, str], base: str, description: str, changes: dict[str, Any], jams: Any
) -> tuple[_Entry, _Entry]:
    """A scene with ``jams`` and the same scene without them (names: with, without)."""
    jammed, healthy = names
    return (
        (jammed, base, description, changes | {"jams": jams}),
        (healthy, base, "the same without jams", changes),
    )


#: (name, base scene, what differs, changes): sudden-jam's variants keep its jams (rollers 4
#: and 9, whose ripples cancel, at 4.5 and 25.0 s).
_ENVELOPE: tuple[_Entry, ...] = (
    *_with_and_without_jams(
        ("ramp-jams", "ramp"),
        "nominal-downhole",
        "100 to 600 rpm and 10 to 45 kN over 30 s, jams at 12 and 22 s",
        {"profile": _RAMP, "duration_s": 30.0, "seed": 11},
        _RAMP_JAMS,
    ),
    *_with_and_without_jams(
        ("assist-jam", "assist"),
        "nominal-downhole",
        "an assisting load, -20 to -30 kN at 300 rpm (back-driving), a jam at 8 s",
        {"profile": _ASSIST, "duration_s": 20.0, "seed": 13},
        _ASSIST_JAM,
    ),
    ("sudden-jam-100rpm", "sudden-jam", "sudden-jam at 100 rpm", {"profile": {"speed_rpm": 100.0}}),
    ("sudden-jam-650rpm", "sudden-jam", "sudden-jam at 650 rpm", {"profile": {"speed_rpm": 650.0}}),
    (
        "sudden-jam-light",
        "sudden-jam",
        "sudden-jam, a traction of 3-8 kN",
        {"profile": {"traction_load_n": [3000.0, 8000.0]}},
    ),
    (
        "sudden-jam-wall-12kN",
        "sudden-jam",
        "sudden-jam, a wall's radial load up to 12 kN",
        {"radial_load": {"max_n": 12000.0}},
    ),
    (
        "sudden-jam-gear-10",
        "sudden-jam",
        "sudden-jam, a 10:1 gearbox and 0.3 N·m/A",
        _drive_train(gear_ratio=10.0, torque_constant_nm_per_a=0.3),
    ),
    (
        "sudden-jam-direct",
        "sudden-jam",
        "sudden-jam, a direct drive and 1.2 N·m/A",
        _drive_train(gear_ratio=1.0, torque_constant_nm_per_a=1.2),
    ),
    (
        "sudden-jam-other-screw",
        "sudden-jam",
        f"sudden-jam on the screw of papers 001/004 ({OTHER_SCREW})",
        {"actuator": {"preset": OTHER_SCREW}},
    ),
    (
        "nominal-other-screw",
        "sudden-jam",
        "the same without jams",
        {"actuator": {"preset": OTHER_SCREW}, "jams": []},
    ),
    (
        "radial-misalignment-encoder-1024",
        "radial-misalignment",
        "radial-misalignment, an encoder of 1024 counts a turn differenced into the speed",
        {"sensors": {"encoder_counts_per_rev": 1024}},
    ),
    (
        "sudden-jam-encoder-1024",
        "sudden-jam",
        "sudden-jam, an encoder of 1024 counts a turn differenced into the speed",
        {"sensors": {"encoder_counts_per_rev": 1024}},
    ),
    (
        "sudden-jam-current-noise",
        "sudden-jam",
        "sudden-jam, a current noise of 0.2 A (0.05)",
        {"sensors": {"current_noise_std_a": 0.2}},
    ),
    (
        "sudden-jam-supports-0.3s",
        "sudden-jam",
        "sudden-jam, supports of 0.3 s between strokes (2 s)",
        {"profile": _cycle(support_s=0.3)},
    ),
    (
        "sudden-jam-supports-0.5s",
        "sudden-jam",
        "sudden-jam, supports of 0.5 s",
        {"profile": _cycle(support_s=0.5)},
    ),
    (
        "sudden-jam-supports-0.5s-seed-46",
        "sudden-jam",
        "sudden-jam, supports of 0.5 s, another draw of its loads, wall and noise (seed 46)",
        {"profile": _cycle(support_s=0.5), "seed": 46},
    ),
    (
        "nominal-supports-0.3s",
        "nominal-downhole",
        "nominal-downhole, supports of 0.3 s",
        {"profile": _cycle(support_s=0.3)},
    ),
    (
        "nominal-release-0.2s",
        "nominal-downhole",
        "nominal-downhole, the load released in 0.2 s at each stroke end (0.5 s)",
        {"profile": _FAST_RELEASE},
    ),
    (
        "nominal-release-0.2s-set",
        "nominal-downhole",
        "nominal-release-0.2s, run with the release setting (200 rad/s², density 5e13)",
        {"profile": _FAST_RELEASE},
    ),
    (
        "sudden-jam-release-0.2s-set",
        "sudden-jam",
        "sudden-jam, the load released in 0.2 s, run with the release setting",
        {"profile": _FAST_RELEASE},
    ),
    ("sudden-jam-100Hz", "sudden-jam", "sudden-jam sampled at 100 Hz", {"rate_hz": 100.0}),
    (
        "radial-misalignment-50Hz",
        "radial-misalignment",
        "radial-misalignment sampled at 50 Hz (below the input health's 100 Hz)",
        {"rate_hz": 50.0, "truth_rate_hz": 50.0},
    ),
    *_with_and_without_jams(
        ("sine-jam", "sine"),
        "nominal-downhole",
        "sine strokes, 300 rpm, a period of 4 s, 20 kN resisting, 40 s, a jam at 10.3 s",
        {"profile": SINE_PROFILE, "duration_s": 40.0, "seed": 12},
        _SINE_JAM,
    ),
    *_with_and_without_jams(
        ("sine-gravity-jam", "sine-gravity"),
        "nominal-downhole",
        "sine strokes, 10 kN that keeps its sign (gravity-like: resisting forward, driving"
        " reverse), 40 s, a jam at 10.3 s",
        {"profile": SINE_PROFILE | _GRAVITY, "duration_s": 40.0, "seed": 12},
        _SINE_JAM,
    ),
    (
        "sine-slow",
        "nominal-downhole",
        "sine strokes, a period of 40 s, 90 s",
        {"profile": SINE_PROFILE | {"period_s": 40.0}, "duration_s": 90.0, "seed": 12},
    ),
    (
        "sine-tilted",
        "radial-misalignment",
        "sine strokes, 20 kN, a wall of 4-8 kN, the screw tilted 2'",
        {"profile": SINE_PROFILE},
    ),
    (
        "sine-radial",
        "stationary-hold",
        "sine strokes, 20 kN, 3 kN radial",
        {"profile": SINE_PROFILE},
    ),
    (
        "sine-faults",
        "sensor-faults",
        "sine strokes, 20 kN, a wall of 0-8 kN, the sensor faults of sensor-faults",
        {"profile": SINE_PROFILE},
    ),
)


def envelope_scenes() -> list[Scene]:
    """The envelope's scenes, in a fixed order (the same run to run)."""
    return [
        varied_scene(base, name, description, **changes)
        for name, base, description, changes in _ENVELOPE
    ]

"""Time series that flow between the bag/ROS edges, the simulator and the estimator.

Struct-of-arrays containers (numpy, SI units), so a whole bag or scene moves as a few arrays
and the estimator can work on blocks of samples without a Python object per sample.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


def _check_lengths(obj: object) -> None:
    lengths = {f.name: len(getattr(obj, f.name)) for f in fields(obj)}  # type: ignore[arg-type]
    if len(set(lengths.values())) > 1:
        raise ValueError(f"{type(obj).__name__}: fields differ in length: {lengths}")


#: numpy dtype kinds of real numbers: float, signed and unsigned integer (the bag reader and the
#: node give float64; the estimator also takes float32, float16 and integer columns).
_REAL_KINDS = ("f", "i", "u")
_FLOAT64 = np.dtype(np.float64)


def _float64_columns(samples: MotorSamples) -> None:
    """Name the first field of ``samples`` that is not a 1-D array of real numbers, check the
    lengths, and hold every column as float64 (the slow path of MotorSamples' validation).

    Integer columns would let values escape the estimator's checks: uint64 stamps going back
    wrap around in a difference, and ``abs`` of int8 -128 or of the int64 minimum is itself
    negative, so out of range passes as in range. float64 holds every value the checks must
    see. A masked array (an ndarray subclass whose values under the mask are arbitrary) has
    its masked entries set to NaN: each is then rejected and counted as non-finite like any
    other invalid value, and the chunk's valid samples are kept (a ValueError would lose them
    with it).
    """
    for f in fields(samples):
        value = getattr(samples, f.name)
        where = f"{type(samples).__name__}.{f.name}"
        if not isinstance(value, np.ndarray):
            raise ValueError(f"{where}: must be a numpy array, got {type(value).__name__}")
        if value.ndim != 1:
            raise ValueError(
                f"{where}: must be 1-D (one entry per sample), got shape {value.shape}"
            )
        if value.dtype.kind not in _REAL_KINDS:
            raise ValueError(f"{where}: must hold real numbers, got dtype {value.dtype}")
        if np.ma.isMaskedArray(value):
            value = np.ma.filled(value.astype(np.float64), np.nan)
        # The frozen dataclass' own fields, converted once here (no copy when already float64).
        object.__setattr__(samples, f.name, np.asarray(value, dtype=np.float64))
    _check_lengths(samples)


@dataclass(frozen=True)
class MotorSamples:
    """Motor measurements, one entry per sample (``prsm_health_msgs/MotorState``).

    stamp_s: header stamp [s] (may jitter, repeat or go backwards in faulty data).
    current_a: motor current [A]. speed_rad_s: motor speed [rad/s].
    position_rad: motor position [rad], counting turns, or wrapped into one turn (a
    single-turn encoder: the estimator adds the turns from the speeds).
    Values are as received: NaN, inf and out-of-range samples are the estimator's to reject.
    Every column is held as a float64 ndarray (converted on construction: :func:`_float64_columns`).
    """

    stamp_s: FloatArray
    current_a: FloatArray
    speed_rad_s: FloatArray
    position_rad: FloatArray

    def __post_init__(self) -> None:
        """Every field a 1-D numpy array of real numbers (float or integer dtype), all of one
        length; else a ValueError naming the field and the problem (the estimator would fail
        deep inside on a column of shape (n, 1), of objects, or a list). Other dtypes than
        float64, and ndarray subclasses (a masked array), are converted to float64 ndarrays."""
        # Built per chunk in the hot paths (the node: one per few samples), so the common case,
        # four float64 ndarrays, is checked directly (about 0.4 us a call) and kept as it is,
        # no copy; the rest field by field.
        s, c, v, p = self.stamp_s, self.current_a, self.speed_rad_s, self.position_rad
        array = np.ndarray
        if not (
            type(s) is array
            and type(c) is array
            and type(v) is array
            and type(p) is array
            and s.ndim == 1
            and s.shape == c.shape == v.shape == p.shape
            and s.dtype is _FLOAT64
            and c.dtype is _FLOAT64
            and v.dtype is _FLOAT64
            and p.dtype is _FLOAT64
        ):
            _float64_columns(self)

    def __len__(self) -> int:
        return len(self.stamp_s)

    def __getitem__(self, index: slice | BoolArray | IntArray) -> MotorSamples:
        """The samples of a slice (views) or of a mask or index array (copies)."""
        return MotorSamples(
            self.stamp_s[index],
            self.current_a[index],
            self.speed_rad_s[index],
            self.position_rad[index],
        )

    @classmethod
    def concatenate(cls, parts: list[MotorSamples]) -> MotorSamples:
        """One run from consecutive parts."""
        return cls(
            np.concatenate([p.stamp_s for p in parts]),
            np.concatenate([p.current_a for p in parts]),
            np.concatenate([p.speed_rad_s for p in parts]),
            np.concatenate([p.position_rad for p in parts]),
        )


@dataclass(frozen=True)
class TruthSamples:
    """Ground truth of a simulated run (``prsm_health_msgs/GroundTruth`` on ``/truth/state``).

    axial_load_n: signed axial load F (> 0 resists positive rotation; see actuator.py) [N].
    radial_load_n: radial load [N]. loading_case: 1 or 2 (paper 000).
    roller_jammed: (samples, n_rollers) bool; jammed_rollers is its count per sample.
    precision_loss_m: accumulated precision loss (with the scene's wear acceleration) [m].
    friction_torque_nm: PRSM friction torque on the screw, opposing the motion [N m].
    fatigue_damage: Palmgren-Miner damage fraction. screw_speed_rad_s, carrier_angle_rad:
    kinematics. wear_coefficient_factor: the scene's wear coefficient over the preset's.
    """

    stamp_s: FloatArray
    axial_load_n: FloatArray
    radial_load_n: FloatArray
    loading_case: IntArray
    roller_jammed: BoolArray
    precision_loss_m: FloatArray
    friction_torque_nm: FloatArray
    fatigue_damage: FloatArray
    screw_speed_rad_s: FloatArray
    carrier_angle_rad: FloatArray
    wear_coefficient_factor: FloatArray

    def __post_init__(self) -> None:
        _check_lengths(self)

    def __len__(self) -> int:
        return len(self.stamp_s)

    def __getitem__(self, index: slice | BoolArray) -> TruthSamples:
        """The samples of a slice or a mask."""
        return TruthSamples(*(getattr(self, f.name)[index] for f in fields(self)))

    def finite(self) -> BoolArray:
        """Per sample: every real-valued field is finite (a NaN load cannot be scored)."""
        ok = np.ones(len(self), dtype=bool)
        for f in fields(self):
            values = getattr(self, f.name)
            if values.dtype.kind == "f":
                ok &= np.isfinite(values)
        return ok

    @property
    def jammed_rollers(self) -> IntArray:
        """Number of jammed rollers per sample."""
        return np.asarray(self.roller_jammed.sum(axis=1), dtype=np.int64)

    @property
    def jam_onsets(self) -> IntArray:
        """Indices of the samples at which the jammed-roller count rises."""
        return np.flatnonzero(np.diff(self.jammed_rollers) > 0) + 1

"""What a real cell does not know exactly, drawn per trial: the twin's uncertainty model.

The skills plan with the configured cell and the part catalogue; a real cell differs from both.
:class:`Uncertainty` holds the ranges (SI units; every range is a uniform draw, ``+-`` a half
width unless it says otherwise), :meth:`Uncertainty.draw` draws one trial's values from the
trial's generator and :class:`Draws` carries them (``Draws.to_json()``: what the trial's JSON
records). Each error is put into the twin where the real one arises, never added to a result:

* **hand-eye**: the camera sits at the calibrated mount times :meth:`Draws.mount_error`; the
  perception still computes with the calibrated mount (:class:`sim.camera.SimCamera`).
* **floor height**: the cell's fixtures (bin floor, walls) stand ``floor_dz`` higher than the
  layout says; the skills keep the configured floor.
* **part tolerances, mass**: the simulated body is :meth:`Draws.true_part` of the catalogue part.
* **frictions**: pad on the part at S and H, the part on the bin floor at G.
* **FT300**: its stream rate, resolution and noise (:meth:`sim.ft_sensor.SimForceTorqueSensor.
  configure`).
* **command lag**: a target sent to the arm takes effect some control periods later
  (:meth:`sim.arm.SimArm.set_command_lag`).

:meth:`Uncertainty.ideal` turns every error off (``cell pivot --ideal``, for debugging): the
trial is then the one the twin ran before this model, seed for seed (frictions +-20 % about the
planner's, mass +-10 %, the sensor sampled every control step with 0.1 N of noise, no lag). The
errors come from a child of the trial's generator, so the part's pose a seed draws is the same
with the model and without it (:meth:`Uncertainty.draw`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from drivers.parts import Frictions, Part
from drivers.pose import Pose
from drivers.ur5.kinematics import rotvec_to_matrix

#: The FT 300's published figures (Robotiq FT 300 instruction manual): the data stream's rate
#: (16-byte frames "at 100 Hz") and its resolution (Fx, Fy, Fz sent as N x 100, Mx, My, Mz as
#: N*m x 1000, int16), and the signal noise of its specifications (0.1 N per force axis, 0.005
#: N*m per moment axis; quoted in docs/emulator.md, where the emulated stream uses the same).
FT300_RATE_HZ = 100.0
FT300_FORCE_RESOLUTION = 0.01  #: N
FT300_TORQUE_RESOLUTION = 0.001  #: N*m
FT300_FORCE_NOISE = 0.1  #: N, standard deviation per force axis
FT300_TORQUE_NOISE = 0.005  #: N*m, standard deviation per moment axis

#: The twin's sensor before this model: one sample per control step, no rounding, 0.1 N and
#: 0.003 N*m of noise (sim/ft_sensor.py's defaults); what ``--ideal`` keeps.
IDEAL_FORCE_NOISE = 0.1  #: N
IDEAL_TORQUE_NOISE = 0.003  #: N*m


@dataclass(frozen=True)
class Uncertainty:
    """The ranges of one trial's draws (SI; ``+-`` half widths of uniform draws)."""

    #: m, per axis of the optical frame: where the camera really is against the calibrated
    #: mount. A hand-eye calibration (``cell calibrate``) leaves about 1 mm.
    hand_eye_translation: float = 0.001
    #: rad, per axis (the rotation vector's components, optical frame): the calibration's angle
    #: error, about 0.5 deg; at the 0.5 m view it moves what the camera sees by up to 4 mm.
    hand_eye_rotation: float = math.radians(0.5)
    #: m: the bin floor's true height against the layout's (the table, the bin's bottom and the
    #: robot's mount are measured to about +-1.5 mm); the skills keep the configured floor.
    floor_height: float = 0.0015
    #: m, each of the outer diameter, the hole and the length independently: a part's
    #: dimensions against the catalogue's (ordinary tolerances of tubes, cans and bottles).
    part_tolerance: float = 0.0003
    #: relative: the part's mass against the catalogue's (most masses there are estimates).
    mass: float = 0.10
    #: pad on the part at S and at H (each drawn on its own), absolute range; None: the
    #: planner's mu_S, mu_H +- ``friction_spread``. The 2F-85's silicone pads: 1.0 on clean dry
    #: steel (drivers/data/grippers/robotiq_2f85.yaml), 0.25-0.75 and more for silicone rubber
    #: on plastics and cardboard, down to the paper's inferred mu_S 0.2 on an oily steel part.
    mu_pad: tuple[float, float] | None = (0.2, 1.0)
    #: the part on the bin floor at G, absolute range; None: the planner's mu_G +-
    #: ``friction_spread``. Plastic on a steel or plastic bin 0.25-0.4, cardboard 0.3-0.5,
    #: lightly oiled to dry steel on steel up to 0.6 (kinetic 0.57); the paper's 0.4 inside.
    mu_ground: tuple[float, float] | None = (0.25, 0.6)
    #: relative: the spread about the planner's frictions where a range above is None.
    friction_spread: float = 0.20
    #: Hz of the FT300's stream (sample and hold between); None: one sample per control step.
    ft_rate_hz: float | None = FT300_RATE_HZ
    #: N and N*m, the sensor's noise (standard deviation per axis) as its datasheet gives it ...
    ft_force_noise: float = FT300_FORCE_NOISE
    ft_torque_noise: float = FT300_TORQUE_NOISE
    #: ... relative: each unit's noise against that typical figure (units differ; the emulated
    #: stream's tests accept 70-130 % of it), force and moment drawn on their own.
    ft_noise_spread: float = 0.25
    #: N and N*m per count of the stream's int16 values (0: not rounded).
    ft_force_resolution: float = FT300_FORCE_RESOLUTION
    ft_torque_resolution: float = FT300_TORQUE_RESOLUTION
    #: control periods (integers, both ends included) from sending a move or servo target over
    #: RTDE to the controller acting on it: 1-3 periods, 8-24 ms at the CB3's 125 Hz (the
    #: controller picks a command up at its next cycle, its trajectory generator a cycle later).
    lag_steps: tuple[int, int] = (1, 3)

    def __post_init__(self) -> None:
        for name in ("hand_eye_translation", "hand_eye_rotation", "floor_height",
                     "part_tolerance", "mass", "friction_spread", "ft_force_noise",
                     "ft_torque_noise", "ft_noise_spread", "ft_force_resolution",
                     "ft_torque_resolution"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
        for name in ("mu_pad", "mu_ground"):
            span = getattr(self, name)
            if span is not None and not 0.0 <= span[0] <= span[1]:
                raise ValueError(f"{name} must be (low, high) with 0 <= low <= high, got {span}")
        if self.ft_rate_hz is not None and not self.ft_rate_hz > 0.0:
            raise ValueError(f"ft_rate_hz must be > 0 or None, got {self.ft_rate_hz!r}")
        lo, hi = self.lag_steps
        if not 0 <= lo <= hi or int(lo) != lo or int(hi) != hi:
            raise ValueError(f"lag_steps must be integers 0 <= low <= high, got {self.lag_steps}")

    @classmethod
    def ideal(cls, friction_spread: float = 0.20, mass: float = 0.10) -> Uncertainty:
        """Every error of this model off: the twin's trials as they were (module doc)."""
        return cls(
            hand_eye_translation=0.0,
            hand_eye_rotation=0.0,
            floor_height=0.0,
            part_tolerance=0.0,
            mass=mass,
            mu_pad=None,
            mu_ground=None,
            friction_spread=friction_spread,
            ft_rate_hz=None,
            ft_force_noise=IDEAL_FORCE_NOISE,
            ft_torque_noise=IDEAL_TORQUE_NOISE,
            ft_noise_spread=0.0,
            ft_force_resolution=0.0,
            ft_torque_resolution=0.0,
            lag_steps=(0, 0),
        )

    @property
    def is_ideal(self) -> bool:
        return self == Uncertainty.ideal(self.friction_spread, self.mass)

    def draw(
        self, rng: np.random.Generator, nominal: Frictions | None = None, control_hz: float = 125.0
    ) -> Draws:
        """One trial's values from ``rng``, always in the same order: mu_S, mu_H, mu_G and
        the mass from ``rng`` itself (four numbers, where the twin always drew them), then from
        a child generator (``rng.spawn``, which leaves ``rng``'s own stream where it is) the
        hand-eye error (x, y, z, rx, ry, rz), the floor height, the outer diameter, hole and
        length, the FT noise (force, moment) and the lag; a zero range draws nothing. So
        whatever ``rng`` draws next (the part's pose) is the same with or without the model.
        ``nominal``: the planner's frictions (where a range is None); ``control_hz``: the
        control rate the lag counts periods of."""
        nominal = nominal if nominal is not None else Frictions()

        def spread(value: float, rel: float) -> float:
            return value * (1.0 + rng.uniform(-rel, rel))

        def friction(span: tuple[float, float] | None, value: float) -> float:
            if span is None:
                return spread(value, self.friction_spread)
            return float(rng.uniform(*span))

        mu_s = friction(self.mu_pad, nominal.mu_s)
        mu_h = friction(self.mu_pad, nominal.mu_h)
        mu_g = friction(self.mu_ground, nominal.mu_g)
        mass_scale = 1.0 + rng.uniform(-self.mass, self.mass)
        errors = rng.spawn(1)[0]

        def plus_minus(half: float) -> float:
            return float(errors.uniform(-half, half)) if half > 0.0 else 0.0

        translation = [plus_minus(self.hand_eye_translation) for _ in range(3)]
        rotation = [plus_minus(self.hand_eye_rotation) for _ in range(3)]
        floor_dz = plus_minus(self.floor_height)
        outer, hole, length = (plus_minus(self.part_tolerance) for _ in range(3))
        force_noise = self.ft_force_noise * (1.0 + plus_minus(self.ft_noise_spread))
        torque_noise = self.ft_torque_noise * (1.0 + plus_minus(self.ft_noise_spread))
        lo, hi = self.lag_steps
        lag = int(errors.integers(lo, hi + 1)) if hi > lo else int(lo)
        return Draws(
            ideal=self.is_ideal,
            hand_eye_xyz_m=(translation[0], translation[1], translation[2]),
            hand_eye_rotvec_rad=(rotation[0], rotation[1], rotation[2]),
            floor_dz_m=floor_dz,
            outer_dm=outer,
            hole_dm=hole,
            length_dm=length,
            mass_scale=float(mass_scale),
            mu_s=float(mu_s),
            mu_h=float(mu_h),
            mu_g=float(mu_g),
            ft_rate_hz=self.ft_rate_hz,
            ft_force_noise_n=float(force_noise),
            ft_torque_noise_nm=float(torque_noise),
            ft_force_resolution_n=self.ft_force_resolution,
            ft_torque_resolution_nm=self.ft_torque_resolution,
            lag_steps=lag,
            lag_s=lag / control_hz,
        )


@dataclass(frozen=True)
class Draws:
    """What one trial drew (SI): see :class:`Uncertainty` for each quantity's meaning."""

    ideal: bool
    hand_eye_xyz_m: tuple[float, float, float]  #: the true mount in the calibrated one's frame
    hand_eye_rotvec_rad: tuple[float, float, float]  #: its rotation (rotation vector)
    floor_dz_m: float  #: true bin floor height minus the configured one
    outer_dm: float  #: true outer diameter (side) minus the catalogue's
    hole_dm: float  #: true hole minus the catalogue's
    length_dm: float  #: true length minus the catalogue's
    mass_scale: float  #: true mass over the catalogue's
    mu_s: float  #: pad-part friction at S (the outer finger on the top surface)
    mu_h: float  #: pad-part friction at H (the inner finger on the rim)
    mu_g: float  #: part-floor friction at G
    ft_rate_hz: float | None  #: the FT stream's rate; None: a sample every control step
    ft_force_noise_n: float
    ft_torque_noise_nm: float
    ft_force_resolution_n: float
    ft_torque_resolution_nm: float
    lag_steps: int  #: control periods a command to the arm waits before it takes effect
    lag_s: float

    def mount_error(self) -> Pose:
        """The camera's true mount in the frame of the calibrated one (m, rad)."""
        rotation = rotvec_to_matrix(self.hand_eye_rotvec_rad)
        return Pose(np.array(self.hand_eye_xyz_m, float), rotation)

    def true_part(self, part: Part) -> Part:
        """The simulated body's dimensions and mass: the catalogue ``part`` off by the draws."""
        return dataclasses.replace(
            part,
            outer=part.outer + self.outer_dm,
            hole=part.hole + self.hole_dm,
            length=part.length + self.length_dm,
            mass=part.mass * self.mass_scale,
        )

    def to_json(self) -> dict[str, float]:
        """Plain floats, named with their units (``ft_rate_hz`` 0: every control step)."""
        x, y, z = self.hand_eye_xyz_m
        rx, ry, rz = self.hand_eye_rotvec_rad
        return {
            "hand_eye_x_mm": 1e3 * x,
            "hand_eye_y_mm": 1e3 * y,
            "hand_eye_z_mm": 1e3 * z,
            "hand_eye_rx_deg": math.degrees(rx),
            "hand_eye_ry_deg": math.degrees(ry),
            "hand_eye_rz_deg": math.degrees(rz),
            "floor_dz_mm": 1e3 * self.floor_dz_m,
            "outer_dmm": 1e3 * self.outer_dm,
            "hole_dmm": 1e3 * self.hole_dm,
            "length_dmm": 1e3 * self.length_dm,
            "mass_scale": self.mass_scale,
            "mu_s": self.mu_s,
            "mu_h": self.mu_h,
            "mu_g": self.mu_g,
            "ft_rate_hz": 0.0 if self.ft_rate_hz is None else float(self.ft_rate_hz),
            "ft_force_noise_n": self.ft_force_noise_n,
            "ft_torque_noise_nm": self.ft_torque_noise_nm,
            "ft_force_resolution_n": self.ft_force_resolution_n,
            "ft_torque_resolution_nm": self.ft_torque_resolution_nm,
            "lag_steps": float(self.lag_steps),
            "lag_ms": 1e3 * self.lag_s,
        }


__all__ = ["Draws", "Uncertainty"]

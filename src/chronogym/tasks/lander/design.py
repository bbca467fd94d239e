"""Design variables and fixed parameters of the six-legged lander case study.

Two dataclasses split what an optimizer may change from what it may not:

* :class:`LanderDesign` -- the design vector ``theta = (f_y, beta, alpha2)``, checked
  against :data:`DESIGN_BOUNDS` on construction;
* :class:`LanderParams` -- every fixed number of the model (masses, dimensions, touchdown
  condition, honeycomb shape, contact, time step, metric settings), each documented
  with where it comes from.

Units are SI throughout (N, m, kg, s); angles are radians.

Sources used for the fixed values
---------------------------------
* Project Chrono's lunar-lander demo (``Lander`` model class and its drop-test demo,
  2025): a 2000 kg cylindrical body 4 m long and 1 m in diameter, four rigid 1.5 m legs
  at 30 deg from vertical attached 0.6 m off the axis, 10 kg legs, 2 kg foot pads,
  contact friction 0.7, lunar gravity 1.62 m/s^2, a 2 m drop height turned into a
  touchdown speed ``v = sqrt(2 g h)`` and a 1 cm start clearance.  We keep its body
  mass, leg and pad masses, leg inclination (the default ``alpha2``), gravity, drop
  height and clearance, so that the MuJoCo and Chrono versions of the case study land
  a comparable vehicle in the same way; the body is made squat (see
  ``LanderParams.chassis_radius``) and the legs longer, to carry a stroke.
* Where the demo has no counterpart (the honeycomb absorber, the secondary strut, the
  stroke) the values are engineering choices sized for that vehicle; each field says
  how it was sized.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from chronogym.validation import invalid, is_number

__all__ = [
    "DEFAULT_DESIGN",
    "DESIGN_BOUNDS",
    "DESIGN_NAMES",
    "LanderDesign",
    "LanderParams",
]

#: Order of the design variables in :meth:`LanderDesign.to_array`.
DESIGN_NAMES: tuple[str, ...] = ("f_y", "beta", "alpha2")

#: Inclusive bounds of the design variables ``name -> (low, high)``.
#:
#: * ``f_y`` [N]: plateau (yield) crush force of one leg's honeycomb cartridge.  For the
#:   default geometry (2090 kg at 2.55 m/s) the struts bottom out below about 2.3 kN,
#:   run into densification below about 3.5 kN, and 8 kN gives a peak deceleration of
#:   about 3.5 ``a_ref``; 1-15 kN brackets both failure modes (bottoming on the soft
#:   side, high peak deceleration on the stiff side) with margin.
#: * ``beta`` [rad]: leg spread angle.  The six legs are grouped in three pairs centred
#:   on the azimuths 0, 120 and 240 deg; within a pair the two legs sit at
#:   ``+-beta/2`` about the pair's centre.  ``beta = 60 deg`` spaces all six legs evenly
#:   (hexagonal footprint); small ``beta`` bunches them into a tripod-like footprint.
#:   Since ``beta`` and ``120 deg - beta`` give the same lander rotated by 60 deg, the
#:   range 20-100 deg is symmetric about the even layout; the two halves differ only in
#:   how the footprint is oriented relative to a slope or to rocks.
#: * ``alpha2`` [rad]: inclination of the primary strut from the vertical, in the leg's
#:   radial plane.  Larger angles widen the footprint (stability) but turn more of the
#:   vertical load into pad sliding and strut bending, and pad friction then takes a
#:   growing share of the energy away from the honeycomb; beyond
#:   ``atan(1 / friction) ~ 63 deg`` the pads would lock the struts.  The bounds obey
#:   ``0 < alpha_min < alpha2 < alpha_max < pi/2``.
DESIGN_BOUNDS: dict[str, tuple[float, float]] = {
    "f_y": (1_000.0, 15_000.0),
    "beta": (math.radians(20.0), math.radians(100.0)),
    "alpha2": (math.radians(10.0), math.radians(50.0)),
}

_UNITS = {"f_y": "N", "beta": "rad", "alpha2": "rad"}


@dataclass(frozen=True)
class LanderDesign:
    """The design vector ``theta = (f_y, beta, alpha2)``.

    Attributes:
        f_y: plateau crush (yield) force of each leg's honeycomb absorber [N].
        beta: leg spread angle [rad] (azimuthal spread of the two legs of a pair; see
            :data:`DESIGN_BOUNDS`).
        alpha2: primary strut inclination from the vertical [rad].

    Raises:
        ValueError: if a value is not a finite number inside :data:`DESIGN_BOUNDS`
            (bounds inclusive); the message names the variable, the value and the range.
    """

    f_y: float = 4_000.0
    beta: float = math.radians(60.0)
    alpha2: float = math.radians(30.0)

    def __post_init__(self) -> None:
        for name in DESIGN_NAMES:
            raw = getattr(self, name)
            try:
                value = float(raw)
            except (TypeError, ValueError):
                raise ValueError(f"{name}={raw!r} is not a number") from None
            low, high = DESIGN_BOUNDS[name]
            unit = _UNITS[name]
            if not math.isfinite(value) or not low <= value <= high:
                hint = ""
                if unit == "rad":
                    hint = (
                        f" (= {math.degrees(value):.6g} deg; allowed "
                        f"{math.degrees(low):.6g} to {math.degrees(high):.6g} deg)"
                    )
                raise ValueError(
                    f"{name}={value!r} {unit} is outside the allowed range "
                    f"[{low:.6g}, {high:.6g}] {unit}{hint}"
                )
            object.__setattr__(self, name, value)

    @classmethod
    def from_degrees(cls, f_y: float, beta_deg: float, alpha2_deg: float) -> LanderDesign:
        """Build a design with the two angles given in degrees."""
        return cls(f_y=f_y, beta=math.radians(beta_deg), alpha2=math.radians(alpha2_deg))

    @classmethod
    def from_array(cls, x: np.ndarray | list[float] | tuple[float, ...]) -> LanderDesign:
        """Inverse of :meth:`to_array` (order :data:`DESIGN_NAMES`)."""
        values = [float(v) for v in x]
        if len(values) != len(DESIGN_NAMES):
            raise ValueError(f"expected {len(DESIGN_NAMES)} values {DESIGN_NAMES}, got {x!r}")
        return cls(**dict(zip(DESIGN_NAMES, values, strict=True)))

    def to_array(self) -> np.ndarray:
        """``[f_y, beta, alpha2]`` as a float64 array."""
        return np.array([getattr(self, n) for n in DESIGN_NAMES], dtype=np.float64)

    def replace(self, **changes: float) -> LanderDesign:
        """A copy with some variables changed (validated again)."""
        values = {n: getattr(self, n) for n in DESIGN_NAMES}
        values.update(changes)
        return LanderDesign(**values)

    def geometry_key(self) -> tuple[float, float]:
        """The variables that change the model's geometry (``f_y`` does not)."""
        return (self.beta, self.alpha2)


#: Mid-range design used as the reference in tests and examples.
DEFAULT_DESIGN = LanderDesign()


@dataclass(frozen=True)
class LanderParams:
    """Every fixed parameter of the lander model, the touchdown and the metrics.

    Frame: world z is up; the chassis frame has its origin at the chassis centre of
    mass, z along the cylinder axis.  "Leg-local" lengths run along the primary strut.
    """

    # --- environment -------------------------------------------------------------------
    #: Gravitational acceleration [m/s^2]; lunar surface gravity (Chrono demo: 1.62).
    gravity: float = 1.62

    # --- chassis --------------------------------------------------------------------------
    #: Chassis mass [kg] (Chrono demo ``m_lander_mass = 2000``).
    chassis_mass: float = 2_000.0
    #: Chassis cylinder radius [m].  The Chrono demo body is a 4 m x 1 m cylinder; on
    #: six 2 m legs that body is so top-heavy (CoM 3.2 m up, static tip-over angle ~23
    #: deg) that it tipped over on a 10 deg slope with these legs.  We keep its mass, use
    #: a squat 2 m x 1.6 m cylinder (closer to real landers' main bodies):
    #: CoM about 2 m up, static tip-over angle ~42 deg at the default design.
    chassis_radius: float = 1.0
    #: Chassis cylinder length (height) [m]; see ``chassis_radius``.
    chassis_length: float = 1.6

    # --- leg geometry ---------------------------------------------------------------------
    #: Radial distance of the primary-strut hinge from the chassis axis [m]: on a bracket
    #: 10 cm outside the shell, like the Chrono demo's legs (0.6 m on a 0.5 m shell).
    hinge_radius: float = 1.1
    #: Height of the primary-strut hinge above the chassis bottom [m].  Raising the hinge
    #: above the secondary-strut root keeps the angle between primary and secondary strut
    #: at the knee between about 38 and 42 deg over the whole ``alpha2`` range (a
    #: well-conditioned truss).
    hinge_height: float = 0.6
    #: Radial distance of the secondary strut's root on the chassis bottom [m].
    secondary_root_radius: float = 0.8
    #: Primary strut length, hinge to pad ball joint, at zero stroke [m].  Longer than the
    #: demo's 1.5 m rigid leg so that, with the hinge 0.6 m up the side, the chassis still
    #: clears the ground by >= 0.45 m at full stroke for every ``alpha2`` in bounds.
    #: (A pad's distance from the axis is ``hinge_radius + primary_length sin(alpha2)``:
    #: 1.45 to 2.63 m.)
    primary_length: float = 2.0
    #: Distance from the hinge to the knee (where the secondary strut meets the upper
    #: primary strut) along the strut [m].
    knee_distance: float = 1.0
    #: Length of the upper primary strut (outer cylinder) [m].
    upper_length: float = 1.2
    #: Length of the lower primary strut (piston) [m]; it overlaps the upper one by
    #: ``upper_length + lower_length - primary_length`` = 0.2 m at zero stroke.
    lower_length: float = 1.0
    #: Strut tube radius [m] (visual and inertia only; struts do not collide).
    strut_radius: float = 0.04

    # --- leg masses (the demo's 10 kg rigid leg split into the three strut bodies) -------
    #: Upper primary strut (outer cylinder holding the honeycomb) mass [kg].
    upper_mass: float = 6.0
    #: Lower primary strut (piston) mass [kg].
    lower_mass: float = 4.0
    #: Secondary strut mass [kg].
    secondary_mass: float = 3.0

    # --- foot pads ----------------------------------------------------------------------
    #: Pad mass [kg] (Chrono demo ``m_footpad_mass = 2``).
    pad_mass: float = 2.0
    #: Pad disc radius [m] (0.3 m across; the demo's pads are 0.25 m across on 1.5 m
    #: legs).
    pad_radius: float = 0.15
    #: Pad disc half thickness [m] (4 cm thick; the demo's pad is 2 cm thick).
    pad_half_thickness: float = 0.02
    #: Gap between the pad ball joint and the pad's top face [m] (demo: 2 cm offset).
    pad_offset: float = 0.02
    #: Pad/ground Coulomb friction coefficient [-].  An assumed mid-range value for a
    #: pad on regolith (the Chrono demo uses 0.7 for all contacts).  It matters: the pads
    #: slide inward while the struts stroke, friction takes energy away from the
    #: absorbers (they get 69 % of the released energy at the default design) and raises
    #: the vertical load per unit strut force to ``1 / (cos(alpha2) - friction
    #: sin(alpha2))``; the struts would lock for ``tan(alpha2) >= 1 / friction``.
    friction: float = 0.5

    # --- touchdown (Chrono demo drop-test conditions) -------------------------------------
    #: Drop height [m] (Chrono demo ``DROP_HEIGHT = 2``).  The fall itself is not
    #: simulated: the lander starts ``start_clearance`` above the ground moving down at
    #: the touchdown speed ``sqrt(2 g h)`` = 2.55 m/s, and ``E_init = M g h``.
    drop_height: float = 2.0
    #: Horizontal touchdown speed along world +x [m/s] (0: vertical touchdown).
    horizontal_speed: float = 0.0
    #: Start height of the lowest pad above the ground under it [m] (Chrono demo 0.01).
    start_clearance: float = 0.01

    # --- honeycomb absorber (one cartridge in each primary strut) -------------------------
    #: Maximum usable crush stroke [m] (full densification).  Sized for the default
    #: design: ``f_y = 4 kN`` uses 70 % of it (0.21 m); below ~2.3 kN the struts
    #: bottom out.
    max_stroke: float = 0.30
    #: Densification onset as a fraction of ``max_stroke`` [-]; aluminium honeycomb
    #: densifies at 70-80 % nominal strain.
    densification_onset: float = 0.80
    #: Crush force at ``max_stroke`` divided by ``f_y`` [-] (steep densification rise).
    densification_ratio: float = 5.0
    #: Stroke of the initial elastic rise up to ``f_y`` [m]; sets the elastic (load,
    #: unload, reload) stiffness ``k_e = f_y / elastic_stroke``.  3 mm is ~1 % strain of
    #: a 0.3-0.4 m cartridge (pre-crushed aluminium honeycomb: elastic strain of order
    #: 1 %).  The energy it returns on unloading, ``f_y * elastic_stroke / 2`` per leg, is
    #: 6 J per leg at 4 kN, 0.5 % of ``E_init``.
    elastic_stroke: float = 0.003
    #: Damping ratio of the absorber's elastic line [-], referred to one leg's share of
    #: the lander mass: ``c = 2 zeta sqrt(k_e M / 6)``, capped at
    #: ``(lower_mass + pad_mass) / timestep`` so that the explicitly applied force stays
    #: stable on the light piston side.  Acts only while the honeycomb is not crushing,
    #: so the plateau stays exactly at ``f_y``.  It stops the landed vehicle ringing on
    #: the stiff elastic line.
    elastic_damping_ratio: float = 0.2
    #: Hard mechanical stop beyond ``max_stroke`` [m] (slide joint limit).
    stop_margin: float = 0.02

    # --- numerics ---------------------------------------------------------------------------
    #: Physics time step [s].  Resolves the elastic line of the stiffest absorber
    #: (15 kN / 3 mm on a 6 kg piston+pad: period ~7 ms) with ~14 steps per period.
    timestep: float = 0.0005
    #: Physics time step on SCM soil [s] (``Terrain.soil``; the simulation uses
    #: ``min(timestep, soil_timestep)`` there, see ``model.terrain_params``).  The soil force
    #: is explicit and its damping ``R`` (3e4 Pa s/m) acts on the 2 kg pads: ``R * pad area
    #: * dt / pad_mass`` is 0.53 at 0.5 ms, so each tick removes more pad speed than the true
    #: exponential would and the pads sink too little.  Default design on ``"mars"`` soil
    #: (2 cm grid), dt 0.5 / 0.25 / 0.125 / 0.0625 ms: sinkage 14.7 / 16.9 / 18.1 / 18.5 cm,
    #: ``E_abs`` 3667 / 3279 / 3136 / 3096 J, ``a_max`` 14.49 / 15.14 / 15.36 / 15.40 m/s^2,
    #: J 2.18 / 2.47 / 2.57 / 2.60.  0.125 ms is within 2 % of the halved step on all four
    #: (and a 1 cm grid changes them by < 0.5 %); rigid ground is converged at 0.5 ms.  At the
    #: soil study's optimum (3.64 kN, 75.8 deg, 12.4 deg; 0.25 / 0.125 / 0.0625 ms): J 1.204 /
    #: 1.135 / 1.151, ``a_max`` 11.61 / 10.55 / 10.61, sinkage 11.6 / 12.9 / 13.6 cm: J and
    #: ``a_max`` within 1.5 %, the sinkage still 5 % short.  A landing costs ~2 s (rigid ~0.3).
    soil_timestep: float = 0.000125
    #: Time constant of the contact, joint-limit and loop-closure constraints [s]
    #: (MuJoCo ``solref[0]``, critically damped).  MuJoCo's default 0.02 s lets the pads
    #: sink 19 mm and the knee joints open 40 mm under the touchdown loads; 0.004 s gives
    #: 3 mm and 2.5 mm (default design).  This softness stands in for the compliance of
    #: the structure and the ground, and it spreads the touchdown impulse (pads and
    #: pistons kicked sideways at ``v tan(alpha2)``, amplified by friction as ``alpha2``
    #: grows) over a few ms.  Filtered over 5 ms, ``a_max`` followed it (default design,
    #: knee loops alone stiffened: 22 m/s^2 at 0.004 s, 27 at 0.002 s, 29 at 0.001 s;
    #: ``alpha2`` = 50 deg: 54, 80, 112); hence the 20 ms ``accel_window`` (>= 5 time
    #: constants), which brings the spread over 4 / 2 / 1 ms to <= 5 % for designs that
    #: do not bottom out (see mujoco/sim.py).  At the default design the crush plateau
    #: (17.3 m/s^2), strokes and energies change by < 2 %; at extreme designs ``E_abs``
    #: does not (``alpha2`` = 50 deg: 2274 / 2504 / 2571 J), because the soft knee loops
    #: take a large share of the energy there (``energy["joint_loops"]`` in the metrics).
    constraint_timeconst: float = 0.004
    #: Upper limit of a landing's simulated time [s].
    max_time: float = 3.0

    # --- metrics ------------------------------------------------------------------------------
    #: Moving-average window applied to the chassis acceleration [s].  At least five
    #: constraint time constants, so that the touchdown kick of the unsprung masses
    #: (whose duration is the numerical constraint compliance) counts by its impulse,
    #: not its height; shorter than the shortest crush pulse in bounds (~55 ms).  See
    #: mujoco/sim.py for the measurements (5 ms before).
    accel_window: float = 0.020
    #: Weight ``alpha`` of the energy term of the objective [-].
    energy_weight: float = 2.0
    #: Chassis tilt (from the ground plane's normal) above which the landing counts as
    #: tipped over [rad].
    tip_angle: float = math.radians(30.0)
    #: The lander is settled when chassis speed stays below this [m/s] ...
    settle_speed: float = 0.01
    #: ... and angular speed below this [rad/s] ...
    settle_angular_speed: float = 0.02
    #: ... for this long [s].
    settle_time: float = 0.1

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (is_number(value) and math.isfinite(value)):
                raise invalid(f"{f.name}={value!r} must be a finite number", value)
        positive = [
            f.name
            for f in fields(self)
            if f.name not in ("horizontal_speed",) and getattr(self, f.name) <= 0
        ]
        if positive:
            raise ValueError(f"parameters must be > 0: {', '.join(positive)}")
        if not 0 < self.densification_onset < 1:
            raise ValueError(f"densification_onset={self.densification_onset!r} must be in (0, 1)")
        if self.densification_ratio <= 1:
            raise ValueError(f"densification_ratio={self.densification_ratio!r} must be > 1")
        if not self.knee_distance < self.upper_length:
            raise ValueError(
                f"knee_distance={self.knee_distance!r} must be < upper_length={self.upper_length!r}"
            )

    # --- derived quantities -------------------------------------------------------------
    @property
    def leg_mass(self) -> float:
        """Mass of one leg: three strut bodies and a pad [kg]."""
        return self.upper_mass + self.lower_mass + self.secondary_mass + self.pad_mass

    @property
    def total_mass(self) -> float:
        """Mass of the whole lander (chassis and six legs) [kg]."""
        return self.chassis_mass + 6 * self.leg_mass

    @property
    def touchdown_speed(self) -> float:
        """Vertical touchdown speed ``sqrt(2 g h)`` [m/s]."""
        return math.sqrt(2.0 * self.gravity * self.drop_height)

    @property
    def e_init(self) -> float:
        """``E_init = M g h``: gravitational potential energy of the lander at the drop
        height relative to touchdown, i.e. "prior to impact" [J].  Equal to the kinetic
        energy ``M v^2 / 2`` of the vertical touchdown velocity the simulation starts
        with."""
        return self.total_mass * self.gravity * self.drop_height

    def absorber_damping(self, f_y: float) -> float:
        """Viscous coefficient of one absorber's elastic line [N s/m] for yield force
        ``f_y`` (see ``elastic_damping_ratio``)."""
        k_e = f_y / self.elastic_stroke
        c = 2.0 * self.elastic_damping_ratio * math.sqrt(k_e * self.total_mass / 6.0)
        return min(c, (self.lower_mass + self.pad_mass) / self.timestep)

    @property
    def a_ref(self) -> float:
        """Reference deceleration ``v^2 / (2 s_max)`` [m/s^2]: the constant deceleration
        that stops the touchdown speed within the maximum absorber stroke."""
        return self.touchdown_speed**2 / (2.0 * self.max_stroke)

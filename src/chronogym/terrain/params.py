"""Soil parameters of the Soil Contact Model (SCM) and the presets of Project Chrono's demos.

Units are SI. Bekker-Wong pressure ``sigma = (Kc / b + Kphi) * z**n`` (Pa), Mohr-Coulomb
shear strength ``tau_max = cohesion + sigma * tan(friction_angle)``, Janosi-Hanamoto shear
``tau = tau_max * (1 - exp(-j / janosi_shear))``; unloading and reloading below the yield
pressure follow ``elastic_stiffness`` (Pa/m), and ``damping`` (Pa s/m) adds pressure
proportional to the speed of a body point moving into the soil.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from chronogym.validation import invalid, is_number

__all__ = ["SOIL_PRESETS", "SoilParameters", "soil_preset"]

# (field, lower bound, lower bound allowed, upper bound or None, unit) for the range checks.
_RANGES: tuple[tuple[str, float, bool, float | None, str], ...] = (
    ("Kphi", 0.0, True, None, "Pa/m^n"),
    ("Kc", 0.0, True, None, "Pa/m^(n-1)"),
    ("n", 0.0, False, None, ""),
    ("cohesion", 0.0, True, None, "Pa"),
    ("friction_angle", 0.0, True, 90.0, "deg"),
    ("janosi_shear", 0.0, False, None, "m"),
    ("elastic_stiffness", 0.0, False, None, "Pa/m"),
    ("damping", 0.0, True, None, "Pa s/m"),
)


@dataclass(frozen=True)
class SoilParameters:
    """Constants of one SCM soil (SI units, friction angle in degrees).

    Field names follow Chrono's ``SCMTerrain::SetSoilParameters``: ``Kphi`` and ``Kc`` are
    Bekker's frictional and cohesive moduli, ``n`` the sinkage exponent, ``cohesion`` and
    ``friction_angle`` the Mohr-Coulomb ``c`` and ``phi``, ``janosi_shear`` the
    Janosi-Hanamoto ``K``, ``elastic_stiffness`` the unloading stiffness and ``damping``
    the viscous ``R``. Invalid values raise ``ValueError`` naming the field.
    """

    Kphi: float
    Kc: float
    n: float
    cohesion: float
    friction_angle: float
    janosi_shear: float
    elastic_stiffness: float
    damping: float

    def __post_init__(self) -> None:
        for name, low, low_ok, high, unit in _RANGES:
            value = getattr(self, name)
            unit_text = f" {unit}" if unit else ""
            expected = f"{'>=' if low_ok else '>'} {low:g}{unit_text}"
            if high is not None:
                expected += f" and < {high:g}{unit_text}"
            if not is_number(value):
                raise invalid(f"{name}={value!r}: expected a finite real number {expected}", value)
            value = float(value)
            in_range = (value >= low if low_ok else value > low) and (high is None or value < high)
            if not math.isfinite(value) or not in_range:
                raise ValueError(f"{name}={value!r}: expected a finite number {expected}")
            object.__setattr__(self, name, value)
        if self.Kphi == 0.0 and self.Kc == 0.0:
            raise ValueError("Kphi=0.0 and Kc=0.0: expected Kphi > 0 or Kc > 0 (soil bears load)")

    @property
    def tan_phi(self) -> float:
        """``tan(friction_angle)``."""
        return math.tan(math.radians(self.friction_angle))

    def replace(self, **changes: float) -> SoilParameters:
        """A copy with some fields changed (validated again)."""
        names = [field.name for field in dataclasses.fields(self)]
        for name in changes:
            if name not in names:
                raise ValueError(f"soil parameter {name!r}: expected one of {', '.join(names)}")
        return dataclasses.replace(self, **changes)


#: Soils of Chrono's SCM demos (``demo_VEH_*_SCM``, ``demo_ROBOT_Viper_SCM``).
SOIL_PRESETS: dict[str, SoilParameters] = {
    "firm": SoilParameters(2e6, 0.0, 1.1, 0.0, 30.0, 0.01, 2e8, 3e4),
    "soft": SoilParameters(0.2e6, 0.0, 1.1, 0.0, 30.0, 0.01, 4e7, 3e4),
    "mars": SoilParameters(0.82e6, 1.4e3, 1.0, 170.0, 35.0, 0.0178, 2e8, 3e4),
    "lete_sand": SoilParameters(5301e3, 102e3, 0.793, 1.3e3, 31.1, 0.012, 2e8, 3e4),
}


def soil_preset(name: str, **changes: float) -> SoilParameters:
    """The preset ``name`` (see ``SOIL_PRESETS``), optionally with some fields changed."""
    try:
        params = SOIL_PRESETS[name]
    except (KeyError, TypeError):
        valid = ", ".join(repr(key) for key in SOIL_PRESETS)
        raise ValueError(f"soil preset {name!r}: expected one of {valid}") from None
    return params.replace(**changes) if changes else params

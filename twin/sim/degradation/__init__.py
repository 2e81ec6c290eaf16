"""Degradation of a preloaded ball nut over operating hours, and the thermal transient after pauses.

The wear state drives the twin's preload, backlash, contact stiffness and drag torque over
operating hours. The chain is:

    operating hours --(Archard)--> wear depth w --(Hertz, ball population)--> preload F, backlash b
    preload F --(catalogue)--> drag torque T, contact stiffness k

Physical picture. The nut is preloaded by oversized balls (or an equivalent offset): each ball is
squeezed into the grooves by an elastic interference delta. Wear of the raceways and balls removes
material at depth w, reducing every interference by w. A ball carries the Hertz point-contact force
Q proportional to delta^(3/2) while delta > 0, and none once delta <= 0; once the balls have lost
contact, the further wear is free axial clearance (backlash). The balls' interferences scatter
(ball-size grade, raceway profile, uneven wear), modelled as a normal distribution, so preload
fades and backlash opens gradually instead of at one instant.

Units: SI everywhere except the names that carry their unit (``hours``, ``_um``, ``_um_per_kh``,
``_K``), which are the units of scenario files and of the paper (operating hours, micrometres).

Sources cited in the docstrings:
- [Archard] J. F. Archard, "Contact and rubbing of flat surfaces", J. Appl. Phys. 24 (1953) 981:
  worn volume (hence depth, at constant contact geometry) proportional to load x sliding distance.
- [Hertz] H. Hertz (1882); K. L. Johnson, *Contact Mechanics*, CUP 1985, ch. 4: for a point contact
  the approach delta and the load Q obey Q = K delta^(3/2), so the contact stiffness
  dQ/ddelta = (3/2) K^(2/3) Q^(1/3) grows as the cube root of the load.
- [Catalogue] THK General Catalog, Ball Screw, "Preload torque" (dynamic preload torque of a
  preloaded nut: T_p = 0.05 (tan beta)^(-1/2) F_a0 Ph / (2 pi)); the same form is in NSK's
  "Precision Machine Components" catalogue. Nut stiffness K_N = 0.8 K (F_a0 / 0.1 C_a)^(1/3)
  (THK/HIWIN catalogues).
- [Paper] Pandhare et al., "Ball Screw Health Monitoring with Inertial Sensors": Table II
  (campaign timeline), section IV (preload loss detected ~2972 h, essentially gone ~6000 h),
  section V / Fig. 13 (backlash ~0 until ~2500 h, rising around 4000 h, ~10 um at 8000 h),
  section III.C (thermal transients after resuming, nominal 2 h warm-up).
- [XJTU] XJTU Ball Screw Degradation Dataset, friction torque per stage
  (Xi'an Jiaotong University ball screw degradation data set, public).

Modules: :mod:`~twin.sim.degradation.wear` (the wear law), :mod:`~twin.sim.degradation.mechanics`
(drag torque and stiffness), :mod:`~twin.sim.degradation.thermal` (the thermal transient),
:mod:`~twin.sim.degradation.xjtu` (the XJTU data and the fit of the law). Every public name is
importable from this package.
"""

from twin.sim.degradation.mechanics import (
    contact_stiffness,
    drag_torque_Nm,
    lead_angle,
    preload_torque_coefficient,
    series_stiffness,
)
from twin.sim.degradation.thermal import hours_since_resume, temperature_rise_K
from twin.sim.degradation.wear import WearLaw, backlash_um, normalised_drag_torque, preload_fraction, wear_depth_um
from twin.sim.degradation.xjtu import (
    XJTU_FILES,
    FrictionTrendFit,
    XjtuSeries,
    fit_friction_trend,
    load_xjtu,
    load_xjtu_directory,
)

__all__ = [
    "WearLaw",
    "wear_depth_um",
    "preload_fraction",
    "backlash_um",
    "normalised_drag_torque",
    "lead_angle",
    "preload_torque_coefficient",
    "drag_torque_Nm",
    "contact_stiffness",
    "series_stiffness",
    "temperature_rise_K",
    "hours_since_resume",
    "XjtuSeries",
    "XJTU_FILES",
    "load_xjtu",
    "load_xjtu_directory",
    "FrictionTrendFit",
    "fit_friction_trend",
]

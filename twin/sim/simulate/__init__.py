"""Running the MuJoCo axis through the paper's routines and turning the motion into sensor streams.

- :class:`World`: what is fixed for a whole campaign (the axis, its rails, its screw) drawn once
  from the scenario seed.
- :class:`Condition`: the axis at one moment of the campaign (preload, backlash, temperature,
  origin set by the operator).
- :class:`Simulator`: one compiled model per time step; :meth:`Simulator.run` rolls it out with
  ``mujoco.rollout`` under a commanded profile.
- :func:`phase1_capture`, :func:`phase2_trajectory` with :func:`phase2_measure_runs` (the motion of a
  session once, then each run's sensors), :func:`dial_indicator`: the three measurement procedures
  of the paper (section III).

Modules: :mod:`~twin.sim.simulate.world` (the world and its effects' forces),
:mod:`~twin.sim.simulate.simulator` (condition, trajectory, simulator, batched rollouts; how the
rails follow the carriage's true position), :mod:`~twin.sim.simulate.phase1`,
:mod:`~twin.sim.simulate.phase2` and :mod:`~twin.sim.simulate.dial` (the procedures). Every public
name is importable from this package.
"""

from twin.sim.simulate.dial import DialResult, dial_indicator
from twin.sim.simulate.phase1 import PHASE1_LEAD_IN, PHASE1_LEAD_OUT, phase1_capture, phase1_measure, phase1_profile
from twin.sim.simulate.phase2 import (
    PHASE2_LEAD_IN,
    phase2_command,
    phase2_measure,
    phase2_measure_runs,
    phase2_moves,
    phase2_trajectory,
    stroke_travels,
    true_error_motions,
)
from twin.sim.simulate.simulator import (
    SETTLE_TIME,
    Condition,
    SimulationDiverged,
    Simulator,
    Trajectory,
    flank_contact_position,
    held_sign,
    run_many,
)
from twin.sim.simulate.world import World, recirculation_force, stribeck_force

__all__ = [
    "SETTLE_TIME",
    "World",
    "recirculation_force",
    "stribeck_force",
    "Condition",
    "SimulationDiverged",
    "Trajectory",
    "Simulator",
    "held_sign",
    "flank_contact_position",
    "run_many",
    "PHASE1_LEAD_IN",
    "PHASE1_LEAD_OUT",
    "phase1_profile",
    "phase1_capture",
    "phase1_measure",
    "PHASE2_LEAD_IN",
    "phase2_moves",
    "phase2_command",
    "phase2_trajectory",
    "phase2_measure",
    "phase2_measure_runs",
    "stroke_travels",
    "true_error_motions",
    "DialResult",
    "dial_indicator",
]

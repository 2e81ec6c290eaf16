"""``twin calibrate``: the twin fitted to a recording, in three layers.

a. **Routine and layout**, measured (:func:`analysis.ingest.routine.measure_recording`: the
   moves' ramps, plateaus and rests fitted over every capture and run), as ``twin scenario
   init`` writes them;
b. **the sensor chain**, measured from the rests (:mod:`analysis.calibration.sensor_chain`: noise
   floors, bandwidths, the torque signal's noise and resolution, the IMU's gravity);
c. **the drive's physical parameters and the Phase I acceleration, jointly**, fitted by indirect
   inference (C. Gouriéroux, A. Monfort and E. Renault, "Indirect inference", J. Appl. Econometrics
   8, 1993): the auxiliary statistics of :mod:`analysis.calibration.drive` (the torque's rigid-body
   fit J and c_v, the drag over the cruise, the ripple at its order, the carriage's pitch (where it
   stands out, else the vertical spectrum's centroid) and lateral suspension mode on the nut
   accelerometers, the gain from the commanded to the IMU's
   axial acceleration at 30-60 Hz in the Phase II runs, and one statistic more than there are
   parameters: the IMU's ringing at the starts and stops, which moves with the velocity loop and
   the vertical trucks and tells apart second solutions of the others) and the routine fit's
   acceleration are computed on the recording's first Phase I sample and on the twin simulated
   with the same layout, averaged over :data:`FIT_SEEDS` seeds (common random numbers: every
   evaluation draws the same noise), and
   ``scipy.optimize.least_squares`` (trust-region reflective, bounds a factor of 10 either side of
   the start) moves the parameters until the two agree best in the statistics' standard errors. The
   Jacobian is differenced at the start (its columns simulated together: one batched rollout per
   capture) and kept up to date between the fit's steps by Broyden's rank-one updates (C. G.
   Broyden, "A class of methods for solving nonlinear simultaneous equations", Math. Comp. 19,
   1965: one simulated point a step where a differenced Jacobian costs one a parameter); at the
   solution it is differenced again, and the fit goes on with it while its Gauss–Newton step
   would still lower the squared residuals (:data:`CONVERGED_CHI2`). A fit that ends more than
   :data:`RESTART_SE` standard errors from the recording starts again from where each parameter's
   own statistic alone would meet it (a Newton step on each from the solution), and the better
   of the two solutions is kept: the statistics the parameters share can hold the joint steps in
   a second minimum. The 90 % intervals
   come from the Jacobian at the solution and the statistics' errors (delta method: Cov = (JᵀJ)⁻¹
   for residuals in units of their standard error); an error is the recording's own (the scatter
   over its captures), the twin's, and the scatter of the statistic over :data:`SPREAD_SEEDS` twin
   seeds at the start (the machine's random geometry and ripple phase, which one recording cannot
   average out); the interval uses the statistics' full covariance over those seeds (Cov = G Σ Gᵀ,
   G = (JᵀWJ)⁻¹JᵀW the weighted least-squares solution's map, W the inverse squared errors: one
   regression gives J and c_v, and a machine's draw moves them together).

Why least_squares and not a black-box optimiser: the statistics are smooth in the parameters (each
responds mostly to one: J to the mass, the cruise's drag to the rails' friction, c_v to the viscous drag, the
ripple amplitude to the ripple, the ramps' slope to the commanded acceleration, a suspension mode's
frequency to the trucks' stiffness in its direction and the mass, the servo's tracking gain from
the command to the IMU, or the speed's overshoot, to the velocity loop's bandwidth), the problem is
small (9 unknowns, 10 statistics), and with common random numbers the residual is deterministic, so a
Gauss–Newton method converges in a few steps where a Bayesian optimiser would need tens of
evaluations; its Jacobian is also what the intervals need.

What the recording cannot inform keeps the twin's default and says why (:data:`NOT_INFORMED`).

Modules: :mod:`.values` (what is fitted, its priors and channels, a calibrated value),
:mod:`.twin_statistics` (the statistics on the twin and the recording), :mod:`.sensors` (layer
b), :mod:`.physical` (layer c), :mod:`.run` (the verb), :mod:`.benchmark` (the blind round trip).
"""

from twin.harness.calibration.physical import fit_physical
from twin.harness.calibration.run import calibrate
from twin.harness.calibration.sensors import corrected_sensor_values, sensor_values
from twin.harness.calibration.values import (
    CALIBRATE_VERSION,
    FITTED,
    NOT_INFORMED,
    PRIOR_FACTOR,
    CalibrationError,
    FitResult,
    Value,
    flagged_keys,
)

__all__ = ["CALIBRATE_VERSION", "FITTED", "NOT_INFORMED", "PRIOR_FACTOR", "CalibrationError", "FitResult", "Value",
           "calibrate", "corrected_sensor_values", "fit_physical", "flagged_keys", "sensor_values"]

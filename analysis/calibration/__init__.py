"""What a recording says about the axis and its instruments, for ``twin calibrate``.

- :mod:`~analysis.calibration.drive`: the motor torque's rigid-body fit (inertia, constant and
  viscous drag) and the torque ripple at its order, per Phase I capture;
- :mod:`~analysis.calibration.sensor_chain`: noise floors, bandwidths and sensitivities of the
  instruments from the spectra of the dwells (the axis at rest).

Both read a recording only (``measurements.h5``); the simulator side
(``twin/harness/calibration/``) compares the same statistics on the twin.
"""

"""Phase I of the paper (section IV): online incipient-fault detection from the nut
accelerometers and the controller's speed and torque. Works on ``measurements.h5`` alone."""
